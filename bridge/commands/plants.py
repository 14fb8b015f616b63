"""Adds `bridge`'s plants to `canalnav run --plant` (scenarios never imports bridge)."""


def register(subparsers) -> None:
    """No subcommand of its own: registers `mavlink-sim` in the scenario runner's PLANTS."""
    from scenarios.loop.runner import PLANTS

    from bridge.autopilot_sim.plant import mavlink_sim_plant

    PLANTS.setdefault("mavlink-sim", mavlink_sim_plant)
