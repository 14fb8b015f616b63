"""`canalnav bench soak`: every scenario file with many seeds; nothing may raise, collide or
fail. Prints one JSON object (runs, failures by kind, rows perception cleaned away) and exits
1 when a run broke the rule."""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

SCENARIO_DIR = Path(__file__).resolve().parents[1]


def register_bench(sub) -> None:
    p = sub.add_parser("soak", help="every scenario file with many seeds: no exception, "
                       "collision or controller failure (JSON)")
    p.add_argument("scenarios", nargs="*", metavar="SCENARIO",
                   help="scenario files (default: every *.toml in the package's scenarios/)")
    p.add_argument("--seeds", type=int, default=20, help="seeds 0..N-1 per file (20)")
    p.add_argument("--first-seed", type=int, default=0, help="start the seeds here (0)")
    p.add_argument("--jobs", type=int, default=None, help="runs at a time (default: cores)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="keep each run's folder here (default: a temporary folder)")
    p.set_defaults(func=run)


def run(args) -> int:
    from controller.errors import InputError
    from scenarios.studies.soak import report, soak

    paths = [Path(p) for p in args.scenarios] or sorted(SCENARIO_DIR.glob("*.toml"))
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise InputError(f"bench soak: no such scenario file: {', '.join(missing)}")
    if args.seeds < 1 or args.first_seed < 0 or (args.jobs is not None and args.jobs < 1):
        raise InputError("bench soak: --seeds and --jobs must be >= 1, --first-seed >= 0")
    seeds = range(args.first_seed, args.first_seed + args.seeds)

    def progress(done, total, r):
        mark = "ok" if r.passed else "FAILED"
        sys.stderr.write(f"[{done}/{total}] {r.scenario} seed {r.seed}: {r.status} ({mark})\n")

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        results = soak(paths, seeds, args.out or tmp, args.jobs, progress)
    out = report(results, time.perf_counter() - t0)
    print(json.dumps(out, indent=2))
    return 0 if out["passed"] else 1
