"""`canalnav fmu build-controller`, `canalnav fmu system` and `canalnav cosim`: the navigation
stack as an FMU, the system of the two FMUs, and its run through OSP's libcosim."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from scenarios.commands.arguments import assignment


def _step(text: str) -> float:
    from controller.errors import InputError
    from scenarios.cosim.system import check_step

    try:
        return check_step(float(text))
    except (ValueError, InputError) as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--step: ")) from None


def _add_scenario_arguments(p) -> None:
    p.add_argument("scenario", help="scenario file (TOML), e.g. scenarios/pohang.toml")
    p.add_argument("--set", action="append", default=[], metavar="PATH=VALUE", type=assignment,
                   help="change a scenario key before it is embedded, as `canalnav run --set` "
                   "(e.g. --set sensors.perception=known-walls); repeatable")
    p.add_argument("--fmi", type=int, choices=(2, 3), default=2,
                   help="FMI version (default 2: pythonfmu; 3: pythonfmu3)")


def register(sub) -> None:
    from fmu.commands.fmu import fmu_actions

    actions = fmu_actions(sub)
    b = actions.add_parser(
        "build-controller", help="build the navigation stack as a co-simulation FMU",
        description="The navigation of a scenario (simulated GPS/AHRS into the EKF, known walls "
        "or the simulated LiDAR, the controller at 10 Hz) as a co-simulation FMU, the scenario "
        "embedded in its resources. Inputs: the boat FMU's outputs; outputs: nT, nS, status, "
        "slack, clearance, cross_track. Runs in a Python with canalnav installed; needs the "
        "cosim extra (pip install 'canalnav[cosim]').")
    _add_scenario_arguments(b)
    b.add_argument("-o", "--out", default="navigation.fmu", help="the FMU file (default "
                   "navigation.fmu)")
    b.set_defaults(func=run_build_controller)

    s = actions.add_parser(
        "system", help="write boat FMU + navigation FMU + connections (OSP and SSP)",
        description="Build both FMUs for a scenario and write them with their connections as "
        "an OSP system structure (OspSystemStructure.xml) and an SSP package (system.ssp), for "
        "`canalnav cosim`, OSP's cosim tool or an SSP importer.")
    _add_scenario_arguments(s)
    s.add_argument("-o", "--out", required=True, help="the system folder")
    s.add_argument("--step", type=_step, default=None, help="communication step in s; must "
                   "divide the IMU period 0.01 s (default 0.01)")
    s.set_defaults(func=run_system)

    c = sub.add_parser(
        "cosim", help="run a system of `canalnav fmu system` through OSP's libcosim",
        description="Run the boat and navigation FMUs of a system folder through libcosim "
        "(libcosimpy) and write log.csv, summary.json and timing.json as `canalnav run` does, "
        "plus the navigation FMU's own log. Exits 0 when the goal is reached and every pass "
        "criterion of the embedded scenario holds, else 1. Needs the cosim extra.")
    c.add_argument("system", help="folder written by `canalnav fmu system`")
    c.add_argument("--out", required=True, help="results folder")
    c.add_argument("--duration", type=float, default=None,
                   help="simulated seconds (default: the scenario's duration_s)")
    c.set_defaults(func=run_cosim_command)


def run_build_controller(args) -> int:
    from scenarios.cosim.build import build_navigation_fmu

    path = build_navigation_fmu(args.scenario, args.out, args.fmi, args.set)
    print(f"wrote {path} (FMI {args.fmi}.0 co-simulation, scenario {args.scenario} embedded)")
    return 0


def run_system(args) -> int:
    from scenarios.cosim.description import SYSTEM_STEP_S
    from scenarios.cosim.system import write_system

    paths = write_system(args.scenario, args.out, args.fmi, args.step or SYSTEM_STEP_S,
                         args.set)
    for kind, path in paths.items():
        print(f"wrote {path}")
    print(f"run it: canalnav cosim {args.out} --out runs/cosim")
    return 0


def run_cosim_command(args) -> int:
    from controller.errors import InputError
    from scenarios.cosim.run import run_cosim
    from scenarios.loop.closed_loop import terminal_progress
    from scenarios.loop.runner import check_criteria

    if args.duration is not None and not args.duration > 0:
        raise InputError(f"--duration: must be positive, got {args.duration:g}")
    progress = terminal_progress() if sys.stderr.isatty() else None
    result = run_cosim(args.system, args.out, args.duration, progress)
    if progress:
        sys.stderr.write("\n")
    print(json.dumps(result.summary, indent=2))
    t = result.timing
    print(f"wall time {t['wall_time_s']:.1f} s, {t['real_time_factor']:.2f}x real time")
    if result.scenario.criteria.min_first_detected_m is not None:
        print("note: criterion min_first_detected_m is not scored here (the segments stay "
              "inside the navigation FMU); `canalnav run` scores it")
    failed = check_criteria(result.scenario, result.summary)
    for f in failed:
        print(f"criterion failed: {f}")
    print(f"results in {Path(args.out)}/: summary.json, timing.json, log.csv, "
          f"navigation_log.csv")
    return 0 if result.summary["reached_goal"] and not failed else 1
