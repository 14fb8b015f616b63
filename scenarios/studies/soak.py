"""A soak of the product: every scenario file with many seeds, and what must never happen.

Each run is a pure function of (scenario file, seed); runs go to worker processes (one per
core by default, each with its LiDAR in its own process: the same results as in parallel).
The pass rule is the product's promise, not the scenarios' criteria: no run raises, no hull
touches anything, no controller fails. Alongside, what perception had to clean away.
"""

from __future__ import annotations

import os
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class SoakRun:
    """One run's outcome (summary figures, or the error that ended it)."""

    scenario: str
    seed: int
    status: str
    reached_goal: bool
    collision: bool
    controller_failed: bool
    error: str  # "" unless the run raised (then the traceback's last lines)
    segments_cleaned: dict
    fallback_steps: int
    wall_s: float

    @property
    def passed(self) -> bool:
        return not (self.error or self.collision or self.controller_failed)


def soak_one(path: str, seed: int, out_dir: str) -> SoakRun:
    """Run one scenario file with one seed (no plots); never raises."""
    from scenarios.loop.runner import run_scenario
    from scenarios.scenario_file import load_scenario

    t0 = time.perf_counter()
    name = Path(path).stem
    try:
        scenario = load_scenario(path)
        name = scenario.name
        s = run_scenario(scenario, Path(out_dir) / f"{name}-seed{seed}", seed=seed, plots=False,
                         parallel_perception=False).summary
    except BaseException as exc:  # a soak records what a run raised, whatever it was
        if isinstance(exc, KeyboardInterrupt):
            raise
        tail = "".join(traceback.format_exception(exc)[-3:]).strip()
        return SoakRun(name, seed, f"raised {type(exc).__name__}", False, False, False, tail,
                       {}, 0, time.perf_counter() - t0)
    return SoakRun(name, seed, s["status"], bool(s["reached_goal"]), bool(s["collision"]),
                   s["status"].startswith("controller failed"), "",
                   dict(s.get("segments_cleaned", {})), int(s.get("fallback_steps", 0)),
                   time.perf_counter() - t0)


def soak(paths, seeds, out_dir, jobs: int | None = None, progress=None) -> list[SoakRun]:
    """Every scenario file in `paths` with every seed, `jobs` at a time (default: cores)."""
    jobs = jobs or os.cpu_count() or 1
    work = [(str(p), int(s)) for p in paths for s in seeds]
    results = []
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = [pool.submit(soak_one, p, s, str(out_dir)) for p, s in work]
        for done, future in enumerate(as_completed(futures), 1):
            results.append(future.result())
            if progress is not None:
                progress(done, len(work), results[-1])
    return sorted(results, key=lambda r: (r.scenario, r.seed))


def report(results: list[SoakRun], wall_s: float) -> dict:
    """The soak's figures: runs, failures by kind, what perception cleaned, per scenario."""
    cleaned: dict[str, int] = {}
    for r in results:
        for k, v in r.segments_cleaned.items():
            cleaned[k] = cleaned.get(k, 0) + int(v)
    per_scenario: dict[str, dict] = {}
    for r in results:
        p = per_scenario.setdefault(r.scenario, {"runs": 0, "reached_goal": 0, "failed": 0})
        p["runs"] += 1
        p["reached_goal"] += r.reached_goal
        p["failed"] += not r.passed
    return {
        "runs": len(results),
        "scenario_files": len(per_scenario),
        "seeds": sorted({r.seed for r in results}),
        "passed": all(r.passed for r in results),
        "exceptions": sum(bool(r.error) for r in results),
        "collisions": sum(r.collision for r in results),
        "controller_failures": sum(r.controller_failed for r in results),
        "reached_goal": sum(r.reached_goal for r in results),
        "fallback_steps": sum(r.fallback_steps for r in results),
        "segments_cleaned": cleaned,
        "per_scenario": per_scenario,
        "failures": [{"scenario": r.scenario, "seed": r.seed, "status": r.status,
                      "error": r.error} for r in results if not r.passed],
        "wall_time_s": round(wall_s, 1),
    }
