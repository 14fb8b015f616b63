"""`canalnav run SCENARIO`: one closed-loop run with metrics and plots."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from scenarios.commands.arguments import assignment, seed_number, whole_number


def params_override(path: str) -> tuple[str, str]:
    """--params TOML as the --set it stands for: [controller.boat] file = the absolute path
    (a path in a scenario is read from the scenario's folder; this one from where the command
    runs). A missing file is named at once."""
    from controller.errors import InputError

    file = Path(path)
    if not file.is_file():
        raise InputError(f"--params {path}: no such parameter file")
    return ("controller.boat.file", str(file.resolve()))


def load_with_overrides(path: str, overrides):
    """The scenario file with the --set overrides applied (each checked as in the file)."""
    from scenarios.scenario_file import load_scenario

    if not overrides:
        return load_scenario(path)
    from scenarios.studies.overrides import scenario_with_overrides

    scenario = load_scenario(path)  # the file as it is must be valid too
    text = Path(path).read_text(encoding="utf-8")
    return scenario_with_overrides(text, str(path), overrides, path=scenario.path,
                                   given_at=lambda p: f"--set {p}")


def add_viz_arguments(p, live: bool = True) -> None:
    """--mcap/--no-mcap, --mcap-points and (for a single run) --live."""
    from scenarios.results.mcap_log import DEFAULT_CLOUD_POINTS

    p.add_argument("--mcap", action=argparse.BooleanOptionalAction, default=False,
                   help="write run.mcap for Foxglove (frames, LiDAR cloud, walls, segments, "
                   "plan, hull circles, tracks, GPS fix, per-step figures); needs the viz extra "
                   "(pip install 'canalnav[viz]'). Default: not written, as it is about 20 MB "
                   "a simulated minute with the LiDAR cloud (--mcap-points 0: about 1 MB)")
    p.add_argument("--mcap-points", type=whole_number(0), default=DEFAULT_CLOUD_POINTS,
                   metavar="N", help="LiDAR points kept per scan for run.mcap and --live, "
                   f"every k-th (default {DEFAULT_CLOUD_POINTS}; 0: no cloud)")
    if live:
        p.add_argument("--live", metavar="[HOST:]PORT",
                       help="serve the run live to Foxglove (Foxglove WebSocket, "
                       "ws://HOST:PORT) with the channels of run.mcap; HOST is 127.0.0.1 "
                       "(this machine only) unless given, e.g. 0.0.0.0:8765 for the network. "
                       "Needs the viz extra")


def register(sub) -> None:
    p = sub.add_parser(
        "run", help="run a canal scenario in closed loop (FMU plant, simulated sensors)",
        description="Run a scenario: the boat FMU as plant, GPS/AHRS into an EKF, LiDAR "
        "detections (or known walls) into the controller at 10 Hz. Writes log.csv (as it "
        "goes), summary.json, timing.json and PNG plots to --out, and with --mcap run.mcap "
        "for Foxglove (the viz extra: pip install 'canalnav[viz]'). Exits 0 when the goal "
        "is reached and every pass criterion holds, else 1.",
    )
    p.add_argument("scenario", help="scenario file (TOML), e.g. scenarios/pohang.toml")
    p.add_argument("--controller", metavar="NAME",
                   help="override the scenario's controller: nmpc (the paper's NMPC), los-pid "
                   "(baseline 1: the NMPC's planner at 1 Hz + LOS-PID), lexicographic "
                   "(baseline 2: the paper's Appendix planner + LOS-PID) or los-pid-waypoints "
                   "(LOS-PID on the waypoints, no planner: blind to walls)")
    p.add_argument("--set", action="append", default=[], metavar="PATH=VALUE", type=assignment,
                   help="change a scenario key by its dotted path, as a TOML value (e.g. "
                   "--set current.east_mps=0.2 --set plant.boat.Nr=-2500); repeatable")
    p.add_argument("--params", metavar="TOML",
                   help="the controller's model from this parameter file (canalnav sysid -o, "
                   "canalnav params), the plant keeping the scenario's boat: as --set "
                   "controller.boat.file=TOML")
    p.add_argument("--out", default=None, help="output folder (default runs/<scenario>-<controller>)")
    p.add_argument("--seed", type=seed_number, default=None,
                   help="noise seed, a whole number >= 0 (default: the scenario's)")
    p.add_argument("--plant", default="fmu", metavar="NAME",
                   help="the boat simulated: fmu (default: the boat FMU), python-model (the "
                   "CasADi model stepped in Python) or mavlink-sim (the FMU behind a simulated "
                   "ArduPilot Rover, driven over MAVLink as canalnav bridge does)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--water", choices=("estimated", "still", "true"), default=None,
                   help="what the NMPC knows of the current and its model's error: the on-line "
                   "estimate, nothing, or the scenario's true current (default: the "
                   "scenario's [controller.options] water, else estimated)")
    add_viz_arguments(p)
    p.add_argument("--serial-perception", action="store_true",
                   help="scan and detect in this process, not in a worker on another core "
                   "(same results, more wall time)")
    p.set_defaults(func=run)


def run(args) -> int:
    from scenarios.loop.closed_loop import log_progress, terminal_events, terminal_progress
    from scenarios.loop.runner import check_criteria, run_scenario

    overrides = list(args.set)
    if args.params:
        overrides.append(params_override(args.params))
    scenario = load_with_overrides(args.scenario, overrides)
    if args.water is not None:
        from scenarios.loop.runner import with_water

        scenario = with_water(scenario, args.water)
    controller = args.controller or scenario.controller
    out = Path(args.out or f"runs/{scenario.name}-{controller}")
    tty = sys.stderr.isatty()  # a bar redrawn in a terminal, else a line every 5 s
    progress = terminal_progress() if tty else log_progress()
    live = viz_request(args)
    result = run_scenario(scenario, out, controller=controller, seed=args.seed,
                          plant=args.plant, plots=not args.no_plots, progress=progress,
                          parallel_perception=False if args.serial_perception else None,
                          events=terminal_events(tty), mcap=args.mcap,
                          live=live, cloud_points=args.mcap_points,
                          invocation={"command_line": shlex.join(getattr(args, "argv", [])) or None,
                                      "overrides": [f"{p}={v!r}" for p, v in overrides]})
    if tty:
        sys.stderr.write("\n")
    s, t = result.summary, result.timing
    print(json.dumps(s, indent=2))
    print(f"solve time per step: mean {t['solve_ms']['mean']:.2f} ms, p99 "
          f"{t['solve_ms']['p99']:.2f} ms, max {t['solve_ms']['max']:.2f} ms; "
          f"{t['real_time_factor']:.1f}x real time")
    failed = check_criteria(scenario, s)
    for f in failed:
        print(f"criterion failed: {f}")
    print(f"results in {out}/: {', '.join(_written(out, args))}")
    return 0 if s["reached_goal"] and not failed else 1


def viz_request(args):
    """--live as (host, port) (None without it); the viz extra checked for --live and --mcap.
    run.mcap is written only with --mcap (see scenarios/README.md, "Looking at a run in
    Foxglove": its size, and the same files on every install)."""
    from scenarios.results.foxglove_messages import require_viz
    from scenarios.results.mcap_log import parse_live

    live = parse_live(args.live) if getattr(args, "live", None) else None
    if live is not None or args.mcap:
        require_viz()
    return live


def _written(out: Path, args) -> list[str]:
    """The files this run writes into `out` (plots only when asked for), that exist."""
    names = ["summary.json", "timing.json", "log.csv", "segments.csv", "snapshots.json",
             "tracks.csv", "vessels.csv", "run.mcap"]
    if args.plant == "mavlink-sim":
        names.append("mavlink.tlog")
    if not args.no_plots:
        names += ["trajectory.png", "separation.png", "states.png"]
    return [n for n in names if (out / n).exists()]
