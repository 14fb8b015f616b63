"""`canalnav compare SCENARIO`: the NMPC against the paper's two baselines."""

from __future__ import annotations

from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser(
        "compare", help="run the NMPC and the paper's two baselines on one scenario",
        description="Runs nmpc, los-pid (baseline 1: NMPC planner at 1 Hz + LOS-PID) and "
        "lexicographic (baseline 2: the paper's Appendix planner + LOS-PID) on the same "
        "scenario and seed. Each run writes its own summary.json (and with --mcap its run.mcap, "
        "see canalnav run) under DIR/<controller>; "
        "DIR gets compare.md, compare.json and one separation plot of all three.",
    )
    p.add_argument("scenario", help="scenario file (TOML)")
    p.add_argument("--out", default=None, help="output folder (default runs/compare-<scenario>)")
    p.add_argument("--seed", type=int, default=None, help="noise seed (default: the scenario's)")
    p.add_argument("--controllers", default="nmpc,los-pid,lexicographic",
                   help="comma-separated controllers to compare, of nmpc, los-pid, "
                   "lexicographic and los-pid-waypoints (default nmpc,los-pid,lexicographic)")
    p.add_argument("--plant", default="fmu", metavar="NAME",
                   help="the boat simulated: fmu (default) or python-model")
    from scenarios.commands.run import add_viz_arguments

    add_viz_arguments(p, live=False)
    p.set_defaults(func=run)


def run(args) -> int:
    from controller.errors import InputError
    from scenarios.studies.compare import compare, text_table
    from scenarios.loop.runner import CONTROLLERS
    from scenarios.scenario_file import load_scenario

    scenario = load_scenario(args.scenario)
    names = [c.strip() for c in args.controllers.split(",") if c.strip()]
    for name in names:
        if name not in CONTROLLERS:
            raise InputError(f"--controllers: unknown controller {name!r} (choose from {', '.join(CONTROLLERS)})")
    from scenarios.commands.run import viz_request

    viz_request(args)
    out = Path(args.out or f"runs/compare-{scenario.name}")
    rows = compare(scenario, out, names, seed=args.seed, plant=args.plant, mcap=args.mcap,
                   cloud_points=args.mcap_points)
    print(text_table(rows))
    print(f"\nwrote {out}/compare.md, {out}/compare.json, {out}/separation.png and one folder per controller")
    return 0
