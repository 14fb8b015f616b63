"""`canalnav bench soak`: every scenario file with many seeds on the study engine (a local
Dask cluster, or `--scheduler`); nothing may raise, collide or fail. Prints one JSON object
(runs, failures by kind, rows perception cleaned away) and exits 1 when a run broke the rule.
With `--out DIR` the study's folder (results table, report, each run's folder) stays there
and `--resume` continues it."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path


def register_bench(sub) -> None:
    from scenarios.commands.sweep import add_engine_options

    p = sub.add_parser("soak", help="every scenario file with many seeds: no exception, "
                       "collision or controller failure (JSON; needs the [sweep] extra)",
                       description="Runs every scenario file (or the SCENARIOs given) with "
                       "--seeds seeds each on the study engine (a local Dask cluster, or "
                       "--scheduler): no run may raise, collide or fail its controller. Prints "
                       "one JSON object (runs, failures by kind, rows perception cleaned away) "
                       "and exits 1 when a run broke the rule. With --out DIR the study's folder "
                       "(results table, report.md, each run's folder) stays there and --resume "
                       "continues it. Needs the sweep extra (pip install 'canalnav[sweep]').")
    p.add_argument("scenarios", nargs="*", metavar="SCENARIO",
                   help="scenario files (default: every *.toml in the package's scenarios/)")
    p.add_argument("--seeds", type=int, default=20, help="seeds per file (20)")
    p.add_argument("--first-seed", type=int, default=0, help="start the seeds here (0)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="keep the study's folder here (default: a temporary folder)")
    add_engine_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from controller.errors import InputError
    from scenarios.studies.soak import report, scenario_files, soak_study
    from scenarios.commands.sweep import check_engine_options
    from scenarios.studies.sweep import require_dask, run_study

    check_engine_options(args)
    paths = [Path(p) for p in args.scenarios] or scenario_files()
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise InputError(f"bench soak: no such scenario file: {', '.join(missing)}")
    if args.seeds < 1 or args.first_seed < 0:
        raise InputError("bench soak: --seeds must be >= 1 and --first-seed >= 0")
    if args.resume and not args.out:
        raise InputError("bench soak: --resume needs the --out folder of the soak to continue")
    study = soak_study(paths, range(args.first_seed, args.first_seed + args.seeds))
    require_dask()
    with tempfile.TemporaryDirectory() as tmp:
        outcome = run_study(study, args.out or Path(tmp) / "soak", scheduler=args.scheduler,
                            workers=args.workers, resume=args.resume,
                            progress=not args.quiet, timeout_s=args.connect_timeout)
    out = report(outcome.rows, outcome.wall_s)
    out["workers"] = outcome.workers
    out["where"] = outcome.where
    print(json.dumps(out, indent=2))
    return 0 if out["passed"] and out["runs"] == len(study.runs) else 1
