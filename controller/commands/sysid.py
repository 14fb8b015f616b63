"""`canalnav sysid`: identify the boat from manoeuvre logs; `canalnav bench sysid`."""

from __future__ import annotations


def _fix(text: str) -> tuple[str, float]:
    import argparse

    name, sep, value = text.partition("=")
    try:
        if not sep:
            raise ValueError
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE (e.g. m11=1900), got {text!r}")


def register(sub) -> None:
    p = sub.add_parser(
        "sysid", help="identify the boat's parameters from manoeuvre logs",
        description="Solves the paper's identification NLP (eq. SI) with IPOPT: surge from "
        "the straight runs (W = diag(0,0,0,1,0,0)), then sway-yaw from the turning runs "
        "(W = diag(1,1,100,0,100,100)) with the surge part fixed. Runs are told apart by their "
        "'# maneuver:' header, else by content (|nS| <= 1 %% throughout: surge). Runs with "
        "'# use: heldout' (or given with --heldout) never enter the fit; they check it. The "
        "logs fix the parameters up to one common scale: m11 is fixed from the weight plus "
        "Soding's added-mass estimate unless --fix names another surge parameter.",
    )
    p.add_argument("logs", nargs="+", metavar="LOG", help="CSV manoeuvre logs")
    p.add_argument("-o", "--out", metavar="TOML", help="write the identified parameters here")
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")
    p.add_argument("--fix", type=_fix, action="append", default=[], metavar="NAME=VALUE",
                   help="hold a parameter at VALUE (SI; repeatable). Fixing Xu, Xuu or c "
                   "instead of m11 moves the scale anchor there")
    p.add_argument("--heldout", action="append", default=[], metavar="LOG",
                   help="a log used only to check the fit (repeatable)")
    p.add_argument("--all-terms", action="store_true",
                   help="fit every sway-yaw term at once instead of adding the quadratic and "
                   "cross terms one at a time when the data determine them")
    p.add_argument("--mass", type=float, default=1700.0, help="weight in kg (default 1700)")
    p.add_argument("--length", type=float, default=7.9, help="length in m (default 7.9)")
    p.add_argument("--breadth", type=float, default=2.6, help="breadth in m (default 2.6)")
    p.set_defaults(func=run)


def register_bench(bench) -> None:
    p = bench.add_parser(
        "sysid", help="time log generation and each identification stage",
        description="Generates the identification logs (seeded, realistic noise) in memory, "
        "identifies the boat and prints the wall time of each stage and IPOPT's iterations "
        "as JSON.",
    )
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--quick", action="store_true", help="the shorter set of runs")
    p.set_defaults(func=bench_run)


def _config(args):
    import math

    from controller.errors import InputError
    from controller.identification.sysid import BoatDimensions, SysidConfig

    for name in ("mass", "length", "breadth"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"--{name}: must be a positive number, got {value!r}")
    dims = BoatDimensions(mass_kg=args.mass, length_m=args.length, breadth_m=args.breadth)
    return SysidConfig(dimensions=dims, fixed=dict(args.fix), select=not args.all_terms)


def run(args) -> int:
    import dataclasses
    import json

    from controller.identification.logs import read_log
    from controller.identification.sysid import format_table, identify, result_to_dict

    config = _config(args)
    logs = [read_log(path) for path in args.logs]
    logs += [dataclasses.replace(log, meta={**log.meta, "use": "heldout"})
             for log in (read_log(path) for path in args.heldout)]
    result = identify(logs, config)
    if args.json:
        print(json.dumps(result_to_dict(result), indent=2))
    else:
        print(format_table(result))
    if args.out:
        fitted = [s for st in result.stages for s in st.logs]
        header = ("identified by canalnav sysid from " + ", ".join(fitted) + "\n"
                  + f"scale: {result.anchor_note}")
        dropped = [r.name for r in result.parameters if r.role == "left out"]
        if dropped:
            header += "\nleft at 0 (the logs do not determine them): " + ", ".join(dropped)
        result.params.save_toml(args.out, header=header)
        if not args.json:
            print(f"\nwrote {args.out}")
    return 0


def bench_run(args) -> int:
    import json
    import time

    from controller.identification.maneuvers import PAPER_RUNS, QUICK_RUNS, generate
    from controller.identification.sysid import SysidConfig, identify

    t0 = time.perf_counter()
    logs = generate(seed=args.seed, noise="realistic",
                    runs=QUICK_RUNS if args.quick else PAPER_RUNS)
    t1 = time.perf_counter()
    result = identify(list(logs.values()), SysidConfig())
    t2 = time.perf_counter()
    out = {
        "target": "sysid",
        "seed": args.seed,
        "runs": "quick" if args.quick else "paper",
        "generate_logs_s": round(t1 - t0, 3),
        "stages": {
            s.name: {"samples": s.n_samples, "nlp_solves": s.passes,
                     "ipopt_iterations": s.iterations,
                     "build_s": round(s.build_s, 3), "solve_s": round(s.solve_s, 3),
                     "covariance_s": round(s.covariance_s, 3), "status": s.status}
            for s in result.stages
        },
        "heldout_check_s": round(result.heldout_s, 3),
        "identify_total_s": round(t2 - t1, 3),
        "total_s": round(t2 - t0, 3),
    }
    print(json.dumps(out))
    return 0
