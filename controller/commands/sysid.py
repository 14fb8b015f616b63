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
        "'# maneuver:' header, else by content (|nS| <= 1 % throughout: surge). Runs with "
        "'# use: heldout' (or given with --heldout) never enter the fit; they check it. The "
        "logs fix the parameters up to one common scale: m11 is fixed from the weight plus "
        "Soding's added-mass estimate unless --fix names another surge parameter. A LOG may be "
        "an ArduPilot DataFlash log (.BIN) of the boat itself: state from the EKF's messages "
        "(XKF1, else POS/GPS, ATT, IMU), commands from the servo outputs (RCOU with the "
        "SERVOn_* in its PARM records), the runs found in it (steady throttle steps, zigzags) "
        "or cut with --window. By default each stage is solved twice: with W, then with each "
        "fitted channel weighted by its own residual noise (an AR(1) model of the first "
        "fit's residuals, whitened): an EKF's errors wander, and W would let the wandering "
        "position steer the fit.",
    )
    p.add_argument("logs", nargs="+", metavar="LOG",
                   help="CSV manoeuvre logs, or ArduPilot DataFlash logs (.BIN)")
    p.add_argument("--window", action="append", default=[], metavar="T0:T1",
                   help="identify from this stretch of each .BIN log (seconds since boot, as "
                   "the log's TimeUS; repeatable) instead of the runs found in it")
    p.add_argument("--heldout-window", action="append", default=[], metavar="T0:T1",
                   help="a stretch of each .BIN log used only to check the fit (repeatable)")
    p.add_argument("--sample", type=float, default=0.1, metavar="S",
                   help=".BIN logs are resampled every S seconds (default 0.1)")
    p.add_argument("--actuator-rates", metavar="THR,STEER",
                   help="for .BIN logs whose servo commands jump: the actuators follow them at "
                   "most this fast (%%/s, e.g. 10,40)")
    p.add_argument("--truth", metavar="TOML",
                   help="compare with these parameters (a simulated boat's): true values and "
                   "ratio errors in the table")
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
    p.add_argument("--select-se", type=float, default=None, metavar="T",
                   help="keep an optional sway-yaw term only when its estimate exceeds T "
                   "standard errors (default 3.14: a family-wise 1 %% over the six terms)")
    p.add_argument("--noise-model", choices=("ar1", "fixed"), default="ar1",
                   help="ar1 (default): a second pass weighting each channel by its residual "
                   "noise, AR(1)-whitened; fixed: the paper's W only")
    p.add_argument("--no-heading-bias", dest="heading_bias", action="store_false",
                   help="do not estimate each turning run's heading bias (a compass's, which an "
                   "EKF's heading carries and its velocity over ground does not) with the "
                   "sway-yaw parameters")
    p.add_argument("--time-limit", type=float, default=300.0, metavar="S",
                   help="CPU seconds for the whole identification (default 300): a solve "
                   "still running then stops with an error saying so; optional sway-yaw terms "
                   "not yet tried are left out, with a note")
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
    extra = {} if args.select_se is None else {"select_se": args.select_se}
    return SysidConfig(dimensions=dims, fixed=dict(args.fix), select=not args.all_terms,
                       noise_model=args.noise_model, max_cpu_s=args.time_limit,
                       heading_bias=args.heading_bias, **extra)


def run(args) -> int:
    import dataclasses
    import json

    from controller.identification.logs import read_log
    from controller.identification.sysid import format_table, identify, result_to_dict

    config = _config(args)
    logs = []
    for path in args.logs:
        logs += _read_any(path, args)
    logs += [dataclasses.replace(log, meta={**log.meta, "use": "heldout"})
             for path in args.heldout for log in _read_any(path, args)]
    if args.truth:
        from controller.identification.logs import with_truth_meta
        from controller.params import BoatParams

        truth = BoatParams.from_toml(args.truth)
        logs = [dataclasses.replace(log, meta=with_truth_meta(log.meta, truth)) for log in logs]
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


def _read_any(path: str, args) -> list:
    """A CSV manoeuvre log, or the runs of a DataFlash log (found, or cut by --window)."""
    import sys

    from controller.errors import InputError
    from controller.identification.dataflash import is_dataflash, read_dataflash
    from controller.identification.log_runs import Window, cut_windows, find_runs
    from controller.identification.logs import read_log

    if not (is_dataflash(path) or str(path).lower().endswith(".bin")):
        return [read_log(path)]
    rates = (0.0, 0.0)
    if args.actuator_rates:
        try:
            rates = tuple(float(v) for v in args.actuator_rates.split(","))
            if len(rates) != 2 or min(rates) < 0:
                raise ValueError
        except ValueError:
            raise InputError(f"--actuator-rates {args.actuator_rates!r}: expected THR,STEER in "
                             "%/s, e.g. 10,40") from None
    flight = read_dataflash(path, sample_s=args.sample, actuator_rates=rates)
    say = sys.stderr if args.json else sys.stdout
    print(f"{path}: {flight.n_samples} samples over {flight.time_s[-1] - flight.time_s[0]:.0f} s; "
          + "; ".join(f"{k} from {v}" for k, v in flight.sources.items()), file=say)
    for note in flight.notes:
        print(f"  note: {note}", file=say)
    windows = [Window.parse(w) for w in args.window]
    heldout = [Window.parse(w, "heldout") for w in args.heldout_window]
    if windows:
        runs = cut_windows(flight, windows + heldout)
    else:
        # a run found where a held-out window lies is held out, not fitted as well
        found = [r for r in find_runs(flight)
                 if not any(r.time_s[0] <= w.t1 and r.time_s[-1] >= w.t0 for w in heldout)]
        runs = found + (cut_windows(flight, heldout) if heldout else [])
    if not runs:
        raise InputError(f"{path}: no identification run found (straight throttle steps, "
                         "zigzags); select stretches with --window T0:T1")
    for run in runs:
        print(f"  {run.meta['use']}: {run.meta['description']}", file=say)
    return runs


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
