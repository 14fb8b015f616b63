"""`canalnav sweep SPEC.toml --out DIR`: a study of many runs on dask.distributed.

The study file names scenario files, seeds, controllers and overrides of scenario keys
(`scenarios/studies/sweep_spec.py`, README "Studies"); the runs go to a local cluster (one
worker per core) or to an existing Dask scheduler (`--scheduler tcp://HOST:8786`). Each run's
folder, `results.csv` and `results.json` are written as runs end; `report.md` and the plots
at the end. Exits 0 when every run ran (whatever its outcome), 1 when a run raised.
"""

from __future__ import annotations

from scenarios.commands.arguments import whole_number


def add_engine_options(p) -> None:
    """The options every study command shares: where the runs go and --resume."""
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="an existing Dask scheduler, e.g. tcp://HOST:8786 (its workers need "
                   "only the package; the scenario files travel with the runs); default: a "
                   "local cluster")
    p.add_argument("--workers", type=whole_number(1), default=None, metavar="N",
                   help="workers of the local cluster (default: one per core)")
    p.add_argument("--resume", action="store_true",
                   help="continue the study in --out: skip the runs that finished (runs that "
                   "raised are tried again)")
    p.add_argument("--connect-timeout", type=float, default=10.0, metavar="S",
                   help="seconds to wait for --scheduler (10)")
    p.add_argument("--quiet", action="store_true", help="no progress line on stderr")


def check_engine_options(args) -> None:
    from controller.errors import InputError

    if args.scheduler and args.workers:
        raise InputError("--workers sizes the local cluster; with --scheduler the cluster's "
                         "own workers run the study")
    if not args.connect_timeout > 0:
        raise InputError(f"--connect-timeout must be > 0 seconds, got {args.connect_timeout}")
    if args.scheduler:
        check_scheduler_address(args.scheduler)


def check_scheduler_address(address: str) -> None:
    """A Dask scheduler's address as `[tcp://|tls://]HOST:PORT`: anything else is malformed
    (said so, rather than reported as unreachable after the connect timeout)."""
    from controller.errors import InputError

    proto, sep, rest = address.partition("://")
    if not sep:
        proto, rest = "tcp", address
    host, colon, port = rest.rpartition(":")
    ok = proto in ("tcp", "tls") and colon and host and port.isdigit() and 0 < int(port) < 65536
    if not ok:
        raise InputError(f"--scheduler {address}: malformed; give tcp://HOST:PORT (a Dask "
                         f"scheduler listens on port 8786 by default, e.g. "
                         f"tcp://10.0.0.5:8786)")


def register(sub) -> None:
    p = sub.add_parser(
        "sweep", help="a study of many runs (scenarios x seeds x controllers x overrides) on "
        "dask.distributed",
        description="Run a study file: every combination of its scenario files, controllers, "
        "override values and seeds (or a seeded sample). Each run writes its folder under "
        "DIR/runs/ as it ends; DIR/results.csv and results.json grow run by run; "
        "DIR/report.md and factor-*.png show success rate, clearance and J_c per factor and "
        "the worst runs with the command that reproduces each. Needs the [sweep] extra.")
    p.add_argument("spec", metavar="SPEC.toml", help="the study file")
    p.add_argument("--out", required=True, metavar="DIR", help="the study's folder")
    add_engine_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from scenarios.studies.sweep import require_dask, run_study
    from scenarios.studies.sweep_spec import load_study

    check_engine_options(args)
    study = load_study(args.spec)  # every check before any run, or before a cluster starts
    require_dask()
    outcome = run_study(study, args.out, scheduler=args.scheduler, workers=args.workers,
                        resume=args.resume, progress=not args.quiet,
                        timeout_s=args.connect_timeout)
    print(summary_line(study, outcome, args.out))
    return 0 if all(r["status"] == "ok" for r in outcome.rows) else 1


def summary_line(study, outcome, out) -> str:
    n = len(outcome.rows)
    ok = sum(r["status"] == "ok" for r in outcome.rows)
    good = sum(bool(r.get("success")) for r in outcome.rows)
    rate = (f", {60 * len(outcome.executed) / outcome.wall_s:.2f} runs/min"
            if outcome.executed and outcome.wall_s > 0 else "")
    return (f"study {study.name}: {n}/{len(study.runs)} runs in the table ({len(outcome.executed)} "
            f"run now on {outcome.where} in {outcome.wall_s:.0f} s{rate}; {outcome.skipped} "
            f"kept from before); {n - ok} raised, {good} succeeded; see {out}/report.md")
