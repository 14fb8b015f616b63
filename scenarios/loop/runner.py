"""Run a scenario: build its plant, perception and controller, close the loop, plot.

`run_scenario` is what `canalnav run` and the scenario tests call. Plants other than the
FMU (e.g. the MAVLink plant of `bridge`) register themselves in `PLANTS`, so this package
never imports `bridge`.
"""

from __future__ import annotations

import json

from pathlib import Path
from typing import Callable

from controller.errors import InputError
from scenarios.loop.closed_loop import LoopConfig, RunResult, run_closed_loop
from scenarios.plants.plant import ActuatorLimits, ModelPlant
from scenarios.scenario_file import Scenario

R_B_M = 3.0  # hull circle radius (paper Table "NMPC parameters")
AIR_DRAFT_M = 2.5
"""Height of the boat above the waterline (not published; an open 12-person cruise boat):
bridges with a higher deck are passed under and do not count for clearance."""


def _fmu_plant(scenario: Scenario, out_dir: Path):
    from scenarios.plants.fmu import FmuPlant

    return FmuPlant(scenario.plant_params, ActuatorLimits(*scenario.actuator_rates), out_dir)


def _model_plant(scenario: Scenario, out_dir: Path):
    return ModelPlant(scenario.plant_params, ActuatorLimits(*scenario.actuator_rates))


PLANTS: dict[str, Callable] = {"fmu": _fmu_plant, "python-model": _model_plant}
"""Plant factories by name: f(scenario, out_dir) -> Plant."""


def make_perception(scenario: Scenario, parallel: bool | None = None, cloud_points: int = 0):
    """Known walls, or the simulated LiDAR and detection one control period behind the
    controller (in a worker process if `parallel`; None: when there is a second core);
    `cloud_points` > 0 carries each scan's cloud, decimated, back for the viewer."""
    if scenario.perception == "known-walls":
        from scenarios.sensors.perception import KnownWalls

        return KnownWalls(scenario.world, scenario.known_walls_range_m, AIR_DRAFT_M)
    from scenarios.sensors.lidar import LidarConfig
    from scenarios.sensors.perception_pipeline import DelayedLidarPerception

    return DelayedLidarPerception(scenario.world, seed=scenario.seed,
                                  config=LidarConfig(noise=scenario.lidar_noise),
                                  parallel=parallel, cloud_points=cloud_points)


def make_controller(scenario: Scenario, name: str | None = None):
    name = name or scenario.controller
    if name == "los-pid":
        from scenarios.loop.controllers import nmpc_planned_los_pid

        return nmpc_planned_los_pid(scenario)
    if name == "lexicographic":
        from scenarios.loop.controllers import lexicographic_los_pid

        return lexicographic_los_pid(scenario)
    if name == "los-pid-waypoints":
        from scenarios.loop.controllers import LosPidController

        return LosPidController(scenario.controller_params, scenario.waypoints,
                                _los_pid_config(scenario))
    if name == "nmpc":
        from scenarios.loop.controllers import NmpcController

        return NmpcController(scenario)
    raise InputError(f"controller {name!r} is not available (choose from: {', '.join(CONTROLLERS)})")


def _los_pid_config(scenario: Scenario):
    from controller.baselines.los_pid import LosPidConfig

    return LosPidConfig(target_speed_mps=scenario.target_speed_mps)


CONTROLLERS = ("nmpc", "los-pid", "lexicographic", "los-pid-waypoints")
"""nmpc: the paper's NMPC; los-pid: baseline 1 (NMPC planner at 1 Hz + LOS-PID);
lexicographic: baseline 2 (the Appendix's planner + LOS-PID); los-pid-waypoints: LOS-PID on the
waypoints with no planner (blind to walls: a reference point, not a baseline)."""


def loop_config(scenario: Scenario, seed: int) -> LoopConfig:
    """The closed loop's settings for a scenario: the true outlines a boat of our air draft
    can hit (and when a removed obstacle leaves), the obstacles to watch, the sensors."""
    from controller.perception.feed import FeedConfig
    from scenarios.results.metrics import WatchedObstacle

    world = scenario.world
    hit = [o for o in world.obstacles if o.z_bottom_m < AIR_DRAFT_M]
    return LoopConfig(
        duration_s=scenario.duration_s, waypoints=scenario.waypoints,
        outlines=tuple(world.wall_polylines()) + tuple(o.closed for o in hit),
        walls=tuple(world.wall_polylines()),
        outline_removed_at_s=(None,) * len(world.walls) + tuple(o.remove_at_s for o in hit),
        obstacles=tuple(WatchedObstacle(o.name, o.kind, o.closed, o.remove_at_s) for o in hit),
        desired_separation_m=R_B_M + scenario.d_p_m, goal_radius_m=scenario.goal_radius_m,
        current_ne=scenario.current_ne, seed=seed, gps=scenario.gps, ahrs=scenario.ahrs,
        snapshot_times_s=scenario.snapshot_times_s or _default_snapshots(scenario),
        lidar_outages_s=scenario.lidar_outages_s,
        feed=FeedConfig(max_age_s=scenario.max_scan_age_s),
        current_field=scenario.current_field, target_speed_mps=scenario.target_speed_mps,
        vessels=world.vessels,
    )


def with_water(scenario: Scenario, water: str) -> Scenario:
    """The scenario with the NMPC's knowledge of the water set to `water` (WATER_MODES)."""
    from dataclasses import replace

    from scenarios.scenario_file import WATER_MODES

    if water not in WATER_MODES:
        raise InputError(f"water {water!r}: choose one of {', '.join(WATER_MODES)}")
    options = {k: v for k, v in scenario.controller_options.items() if k != "knows_current"}
    return replace(scenario, controller_options={**options, "water": water})


def run_scenario(scenario: Scenario, out_dir: Path, controller: str | None = None,
                 seed: int | None = None, plant: str = "fmu", plots: bool = True,
                 progress=None, parallel_perception: bool | None = None,
                 events=None, mcap: bool | None = False, live=None,
                 cloud_points: int | None = None, invocation: dict | None = None) -> RunResult:
    """Run one scenario into `out_dir` (log.csv, summary.json, timing.json, PNG plots, and
    run.mcap). `parallel_perception` changes the wall time only, never the results;
    `events(t, text)` hears when the controller starts or stops waiting. `mcap`: write
    run.mcap (default no, as `canalnav run` without --mcap, studies and tests want; None: when
    the viz extra is installed; True without it: InputError naming it);
    `live` (host, port): serve the run to Foxglove over WebSocket; `cloud_points`: points per
    LiDAR cloud in both (0: none). None of these changes the results. `invocation`: how the
    run was asked for (`canalnav run` gives its command line and --set overrides), kept in
    summary.json so that a result says how to make it again."""
    if plant not in PLANTS:
        raise InputError(f"plant {plant!r} is not available (choose from: {', '.join(PLANTS)})")
    if scenario.current_profile is not None and plant not in ("fmu", "python-model"):
        raise InputError(f"{scenario.path or scenario.name}: field 'current.profile': a current "
                         f"that changes along the canal needs the fmu or python-model plant, "
                         f"not {plant}")
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a parent that is a file, a folder without write permission
        raise InputError(f"--out {out_dir}: cannot make the folder: {exc.strerror or exc}"
                         ) from None
    seed = scenario.seed if seed is None else seed
    if seed != scenario.seed:
        from dataclasses import replace

        scenario = replace(scenario, seed=seed)
    cfg = loop_config(scenario, seed)
    viz = _loop_viz(scenario, cfg, out_dir, mcap, live, cloud_points)
    if viz is not None and viz.live_url and events is not None:
        events(0.0, f"live view for Foxglove on {viz.live_url}")
    points = viz.log.options.cloud_points if viz is not None else 0
    # The perception before the controller: a worker process then starts (imports, tables)
    # while this one builds the controller and the plant, instead of stalling the first scan.
    try:
        perception = make_perception(scenario, parallel_perception, points)
    except BaseException:
        _close(viz)
        raise
    try:
        ctrl = make_controller(scenario, controller)
        the_plant = PLANTS[plant](scenario, out_dir)
    except BaseException:
        _close(perception)
        _close(viz)
        raise
    try:
        result = run_closed_loop(the_plant, ctrl, perception, scenario.initial_state, cfg,
                                 out_dir, progress=progress, scenario_name=scenario.name,
                                 events=events, viz=viz)
    finally:
        the_plant.close()
        _close(perception)
        _close(viz)
    if invocation:
        result.summary["invocation"] = dict(invocation)
        (out_dir / "summary.json").write_text(json.dumps(result.summary, indent=2) + "\n")
    if plots:
        from scenarios.results import plots as p

        title = f"{scenario.name}: {result.summary['controller']}"
        p.plot_trajectory(out_dir, scenario.world.surfaces(AIR_DRAFT_M), scenario.waypoints,
                          out_dir / "trajectory.png", title, vessels=scenario.world.vessels)
        p.plot_separation({result.summary["controller"]: out_dir}, cfg.desired_separation_m,
                          out_dir / "separation.png", title)
        p.plot_states(out_dir, out_dir / "states.png", title)
    return result


def _close(thing) -> None:
    close = getattr(thing, "close", None)
    if close is not None:
        close()


def _loop_viz(scenario: Scenario, cfg: LoopConfig, out_dir: Path, mcap, live, cloud_points):
    """The run's MCAP log and live view (`LoopViz`), or None when neither is wanted (or
    run.mcap by default, and the viz extra is not installed). A stale run.mcap of an earlier
    run in the folder is removed when none is written."""
    from scenarios.results.foxglove_messages import require_viz, viz_available

    target = out_dir / "run.mcap"
    if mcap is None:
        mcap = viz_available()
    if not mcap:
        target.unlink(missing_ok=True)
    if not mcap and live is None:
        return None
    require_viz()
    from scenarios.results.mcap_log import DEFAULT_CLOUD_POINTS, LoopViz, VizOptions

    lidar = None
    if scenario.perception != "known-walls":
        from scenarios.sensors.lidar import LidarConfig

        lidar = LidarConfig().mounts
    options = VizOptions(mcap_path=target if mcap else None, live=live,
                         cloud_points=DEFAULT_CLOUD_POINTS if cloud_points is None
                         else int(cloud_points))
    return LoopViz(options, lidar_mounts=lidar or (), origin=scenario.geodetic_origin,
                   hull_radius_m=R_B_M, separation_m=cfg.desired_separation_m,
                   gps_sigma_m=cfg.gps.pos_sigma_m, n_walls=len(scenario.world.walls))

def _default_snapshots(scenario: Scenario) -> tuple:
    """Four instants spread over the expected run time."""
    from controller.geometry import Polyline

    expected = Polyline(scenario.waypoints).length / max(scenario.target_speed_mps, 0.1)
    horizon = min(scenario.duration_s, expected)
    return tuple(round(horizon * f, 1) for f in (0.15, 0.4, 0.65, 0.9))


def check_criteria(scenario: Scenario, summary: dict) -> list[str]:
    """The scenario's pass criteria that the summary fails, as sentences (empty: passed)."""
    c, s, failed = scenario.criteria, summary, []
    if c.reach_goal and not s["reached_goal"]:
        failed.append(f"did not reach the goal ({s['status']}, "
                      f"{s['final_distance_to_goal_m']} m from it)")
    if c.reach_goal_within_s is not None and s["reached_goal"] and s["duration_s"] > c.reach_goal_within_s:
        failed.append(f"reached the goal after {s['duration_s']} s > {c.reach_goal_within_s} s")
    if c.min_clearance_m is not None and (s["min_clearance_m"] or 0) < c.min_clearance_m:
        failed.append(f"min clearance {s['min_clearance_m']} m < {c.min_clearance_m} m")
    if c.max_time_below_desired_s is not None and s["time_below_desired_s"] > c.max_time_below_desired_s:
        failed.append(f"{s['time_below_desired_s']} s below the desired separation > "
                      f"{c.max_time_below_desired_s} s")
    if c.max_mean_cross_track_m is not None and (s["mean_cross_track_m"] or 0) > c.max_mean_cross_track_m:
        failed.append(f"mean cross-track {s['mean_cross_track_m']} m > {c.max_mean_cross_track_m} m")
    # a criterion about a kind of place the run never reached fails: it checked nothing
    width = s["narrow_below_m"]
    wide = s["min_clearance_where_wide_m"]
    if c.min_clearance_where_wide_m is not None:
        if wide is None:
            failed.append(f"min_clearance_where_wide_m: the boat was never where the canal is "
                          f"at least {width:g} m wide")
        elif wide < c.min_clearance_where_wide_m:
            failed.append(f"min clearance where the canal is at least {width:g} m wide "
                          f"{wide} m < {c.min_clearance_where_wide_m} m")
    if c.max_fallback_steps is not None and s.get("fallback_steps", 0) > c.max_fallback_steps:
        failed.append(f"{s['fallback_steps']} steps on a fallback plan > {c.max_fallback_steps}")
    if c.min_first_detected_m is not None:
        for o in s.get("obstacles", []):
            seen = o["first_detected_m"]
            if seen is None or seen < c.min_first_detected_m:
                failed.append(f"obstacle {o['name']!r} first detected "
                              f"{'never' if seen is None else f'{seen:.1f} m away'} "
                              f"(< {c.min_first_detected_m} m)")
    if c.min_time_held_s is not None and s.get("time_held_s", 0.0) < c.min_time_held_s:
        failed.append(f"held at rest for {s.get('time_held_s', 0.0)} s < {c.min_time_held_s} s")
    held = s.get("max_speed_while_held_mps")
    if c.max_speed_while_held_mps is not None and held is not None \
            and held > c.max_speed_while_held_mps:
        failed.append(f"speed while held {held} m/s > {c.max_speed_while_held_mps} m/s")
    swing = s.get("swing_while_waiting_m")
    if c.max_swing_while_waiting_m is not None and swing is not None \
            and swing > c.max_swing_while_waiting_m:
        failed.append(f"swung {swing} m to and fro while waiting > "
                      f"{c.max_swing_while_waiting_m} m")
    for v in s.get("vessels", []):
        d = v["min_hull_distance_m"]
        if c.min_vessel_distance_m is not None and (d is None or d < c.min_vessel_distance_m):
            failed.append(f"vessel {v['name']!r} came within {d} m hull to hull "
                          f"(< {c.min_vessel_distance_m} m)")
        if c.vessels_passed_on is not None and v["passed_on"] != c.vessels_passed_on:
            failed.append(f"vessel {v['name']!r} was passed on the boat's {v['passed_on']} "
                          f"side, not {c.vessels_passed_on}")
        share = v["starboard_half_while_meeting"]
        if c.min_starboard_half_while_meeting is not None and share is not None \
                and share < c.min_starboard_half_while_meeting:
            failed.append(f"in the starboard half {share:.0%} of the time meeting vessel "
                          f"{v['name']!r} (< {c.min_starboard_half_while_meeting:.0%})")
    offset = s["mean_centre_offset_narrow_m"]
    if c.max_mean_centre_offset_narrow_m is not None:
        if offset is None:
            failed.append(f"max_mean_centre_offset_narrow_m: the boat was never where the canal "
                          f"is narrower than {width:g} m")
        elif offset > c.max_mean_centre_offset_narrow_m:
            failed.append(f"mean offset from the middle where the canal is narrower than "
                          f"{width:g} m {offset} m > {c.max_mean_centre_offset_narrow_m} m")
    return failed
