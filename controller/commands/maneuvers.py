"""`canalnav maneuvers`: the paper's identification runs as CSV logs: simulated from the model,
or (`--connect`, options added by `bridge.commands.maneuvers_boat`) driven on the boat."""

from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser(
        "maneuvers", help="simulate the identification manoeuvres as CSV logs",
        description="Simulates the paper's identification runs from the boat model (exact "
        "plant, actuator rate limits 10 and 40 %/s) at 10 Hz with seeded sensor noise: "
        "acceleration 31.0-50.6 %, deceleration 50.6-20.0 % (each held to steady state), a "
        "20 deg/50 % zigzag at 42 % (three overshoots) and a held-out 10 deg/30 % zigzag "
        "(header 'use: heldout'). Each log carries the true parameters in its header. With "
        "--connect the same runs are driven on the boat over MAVLink instead (see below).",
    )
    p.add_argument("-o", "--out", required=True, metavar="DIR", help="directory for the logs")
    p.add_argument("--seed", type=int, default=1, help="noise seed (default 1)")
    p.add_argument("--noise", choices=("realistic", "none"), default="realistic",
                   help="realistic: RTK GPS 0.02 m, heading 0.1 deg, speed 0.02 m/s, yaw rate "
                   "0.2 deg/s (1 sigma); none: exact states")
    p.add_argument("--params", metavar="TOML", help="simulate this boat (default: the "
                   "paper's identified parameters)")
    p.add_argument("--quick", action="store_true",
                   help="fewer throttle steps and a looser steady state (for quick trials)")
    p.add_argument("--overshoots", type=int, default=None, metavar="N",
                   help="overshoots of the fit zigzag (default 3, the paper's; the held-out "
                   "zigzag keeps its own): a longer zigzag for a noisier state, e.g. an EKF's")
    p.set_defaults(func=run)


def run(args) -> int:
    from controller.errors import InputError

    if getattr(args, "connect", None):
        if args.params:
            raise InputError("maneuvers: --params simulates a boat; with --connect the boat "
                             "is real")
        return args.connect_func(args)
    if getattr(args, "scenario", None):
        raise InputError("maneuvers: --scenario is for --connect (driving the runs on the boat)")
    return simulate(args)


def simulate(args) -> int:
    from controller.identification.maneuvers import (PAPER_RUNS, QUICK_RUNS, generate,
                                                     with_overshoots, write_logs)
    from controller.params import IDENTIFIED, BoatParams

    params = BoatParams.from_toml(args.params) if args.params else IDENTIFIED
    runs = with_overshoots(QUICK_RUNS if args.quick else PAPER_RUNS, args.overshoots)
    logs = generate(params, seed=args.seed, noise=args.noise, runs=runs)
    paths = write_logs(args.out, logs)
    for path, log in zip(paths, logs.values()):
        print(f"{path}: {log.meta['description']}; {log.n_samples} samples, "
              f"{log.time_s[-1] - log.time_s[0]:.1f} s"
              + (" (held out)" if log.heldout else ""))
    return 0
