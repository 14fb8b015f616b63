"""`canalnav bench loop`: how fast the closed loop runs, and where its time goes.

Runs one scenario (default: the Pohang canal, NMPC, LiDAR and EKF in the loop) with the
LiDAR in a worker process and in this process, alternately `--repeats` times, and prints one
JSON object: real-time factor and per-step milliseconds of each part for both, the ratio of
their wall times from the same run, and whether the two gave the same summary. Beside the
wall time, the CPU time of the run (this process and the perception worker's): on a shared
machine the wall time grows with the other processes, the CPU time much less, so
`cpu_real_time_factor` (simulated seconds per CPU second) compares builds across sessions.

`--mcap` compares instead the loop writing run.mcap (and, with `--live`, serving it) against
the same loop without, both with the LiDAR worker: the wall time per step of each, the
writer's own time per step (`viz` in where the time goes), its share of the loop's step,
and whether the summaries agree.
"""

from __future__ import annotations

import json
import math
import statistics
import tempfile
from dataclasses import replace
from pathlib import Path


def register_bench(sub) -> None:
    p = sub.add_parser("loop", help="closed-loop speed (real-time factor, where the time goes), "
                       "LiDAR in a worker process vs in the loop's process",
                       description="Runs one scenario (default: the Pohang canal, NMPC, LiDAR "
                       "and EKF in the loop) with the LiDAR in a worker process and in this "
                       "process, alternately --repeats times, and prints one JSON object: the "
                       "real-time factor and per-step milliseconds of each part for both, the "
                       "ratio of their wall times, their CPU time (cpu_real_time_factor compares "
                       "builds on a shared machine) and whether the two gave the same summary. "
                       "With --mcap it compares the loop writing run.mcap (and, with --live, "
                       "serving it) against the same loop without.")
    p.add_argument("scenario", nargs="?", default=None,
                   help="scenario file (default: scenarios/pohang.toml)")
    p.add_argument("--duration", type=float, default=120.0,
                   help="simulated seconds per run (0: the scenario's own duration)")
    p.add_argument("--repeats", type=int, default=1, help="runs of each mode, alternating")
    p.add_argument("--mcap", action="store_true",
                   help="compare the loop with run.mcap against without it (LiDAR in the "
                   "worker for both) instead of worker against serial")
    p.add_argument("--live", metavar="[HOST:]PORT",
                   help="with --mcap: serve the MCAP run live too (no viewer need connect)")
    p.set_defaults(func=run)


def run(args) -> int:
    from controller.errors import InputError
    from scenarios.loop.runner import run_scenario
    from scenarios.scenario_file import load_scenario

    path = Path(args.scenario) if args.scenario else Path(__file__).resolve().parents[1] / "pohang.toml"
    scenario = load_scenario(path)
    if args.duration < 0 or args.repeats < 1:
        raise InputError("bench loop: --duration must be >= 0 and --repeats >= 1")
    if args.duration > 0:
        scenario = replace(scenario, duration_s=min(args.duration, scenario.duration_s))
    modes = ("mcap", "plain") if args.mcap else ("worker", "serial")
    live = None
    if args.live:
        if not args.mcap:
            raise InputError("bench loop: --live goes with --mcap")
        from scenarios.results.mcap_log import parse_live

        live = parse_live(args.live)
    results = {m: [] for m in modes}
    summaries, sizes = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeats):
            for mode in modes if k % 2 == 0 else modes[::-1]:
                out = Path(tmp) / f"{mode}{k}"
                cpu0 = _cpu_s()
                r = run_scenario(scenario, out, plots=False,
                                 parallel_perception=mode != "serial", mcap=mode == "mcap",
                                 live=live if mode == "mcap" else None)
                r.timing["cpu_s"] = _cpu_s() - cpu0
                results[mode].append(r.timing)
                summaries[mode] = (out / "summary.json").read_text()
                if (out / "run.mcap").exists():
                    sizes[mode] = (out / "run.mcap").stat().st_size
                steps = r.summary["steps"]
    report = {"scenario": scenario.name, "controller": scenario.controller,
              "simulated_s": round(steps * 0.1, 1), "steps": steps, "repeats": args.repeats}
    for mode, timings in results.items():
        report[mode] = _describe(timings, steps)
    def wall(mode):
        return statistics.median(t["wall_time_s"] for t in results[mode])

    if args.mcap:
        viz = statistics.median(t["where_the_time_goes_s"]["viz"] for t in results["mcap"])
        report["mcap_over_plain_wall"] = round(wall("mcap") / wall("plain"), 3)
        report["viz_ms_per_step"] = round(1e3 * viz / steps, 3)
        report["viz_share_of_step"] = round(viz / wall("mcap"), 4)
        report["mcap_bytes_per_step"] = sizes["mcap"] // steps
        report["same_summary"] = summaries["mcap"] == summaries["plain"]
    else:
        report["serial_over_worker_wall"] = round(wall("serial") / wall("worker"), 3)
        report["same_summary"] = summaries["worker"] == summaries["serial"]
    print(json.dumps(report, indent=2))
    return 0


def _cpu_s() -> float:
    """CPU seconds of this process and of its finished children (the perception worker is
    waited for when a run ends)."""
    import resource

    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def _describe(timings: list, steps: int) -> dict:
    """Median real-time factor and per-step times (ms) of the runs of one mode."""
    def per_step_ms(seconds):
        return round(1e3 * statistics.median(seconds) / steps, 3)

    parts = timings[0]["where_the_time_goes_s"].keys()
    out = {"real_time_factor": round(statistics.median(t["real_time_factor"] for t in timings), 2),
           "wall_s": round(statistics.median(t["wall_time_s"] for t in timings), 2),
           "cpu_s": round(statistics.median(t["cpu_s"] for t in timings), 2),
           "cpu_real_time_factor": round(0.1 * steps / statistics.median(
               t["cpu_s"] for t in timings), 2),
           "loop_ms_per_step": {p: per_step_ms([t["where_the_time_goes_s"][p] for t in timings])
                                for p in parts},
           # the loop's own thread's CPU per part (the perception worker's is beside)
           "loop_cpu_ms_per_step": {
               p: per_step_ms([t["where_the_cpu_goes_s"][p] for t in timings])
               for p in timings[0].get("where_the_cpu_goes_s", {})},
           "cpu_ms_per_step": round(1e3 * statistics.median(t["cpu_s"] for t in timings)
                                    / steps, 3)}
    if "perception" in timings[0]:
        out["lidar_ms_per_step"] = {
            p: per_step_ms([t["perception"][f"{p}_s"] for t in timings])
            for p in ("lidar_scan", "detection", "tracking")}
        out["lidar_cpu_ms_per_step"] = {
            p: per_step_ms([t["perception"].get(f"{p}_cpu_s", math.nan) for t in timings])
            for p in ("lidar_scan", "detection", "tracking")}
    out["solve_ms"] = timings[-1]["solve_ms"]
    return out
