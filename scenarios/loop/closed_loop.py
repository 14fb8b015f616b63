"""The closed loop: plant, sensors, navigation filter, perception and controller on sim time.

One control period (0.1 s) is: perceive segments (cleaned, and bridged over a missing scan
for a while by `controller.perception.feed`, or "blind" after that), run the controller on
the estimated state, then step the plant in IMU periods (0.01 s) with the command held,
fusing AHRS every IMU period and GPS at its rate (5 Hz by default); a plant with its own
estimate, such as an autopilot's EKF over MAVLink, replaces the sensors and the filter.
Every control step is appended to the log as it happens, so an interrupted run loses
nothing; the summary and plots come at the end. What perception delivers never ends a run.
"""

from __future__ import annotations

import inspect
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Protocol

import numpy as np

from controller.geometry import Polyline, point_segment_distance
from controller.navigation import NavigationFilter
from controller.nmpc.passage import waiting_kind
from controller.perception.feed import FeedConfig, SegmentFeed
from scenarios.results import metrics
from scenarios.results.encounters import EncounterWatch, TrackingWatch
from scenarios.plants.plant import Plant, PlantFailure, PlantOutput
from scenarios.loop.run_log import RunLog
from scenarios.sensors.gps_ahrs import AhrsConfig, AhrsSensor, GpsConfig, GpsSensor


@dataclass
class Decision:
    """What a controller returns each control period."""

    command: np.ndarray  # [nT, nS] percent, to send now
    ok: bool = True
    status: str = "ok"
    predicted: np.ndarray | None = None  # (K, >=3) predicted x, y, psi, ...
    slack_m: float = 0.0
    segments_used: np.ndarray | None = None  # (M, 4) segments the controller saw
    stats: dict = field(default_factory=dict)


class Controller(Protocol):
    name: str

    def step(self, time_s: float, state: np.ndarray, actuators: np.ndarray,
             segments: np.ndarray, blind: bool = False) -> Decision: ...
    # (`blind` is optional: a controller without it is called with the segments only)


class Perception(Protocol):
    """Where the segments come from: detections from a simulated LiDAR, or known walls.
    None: no scan this period (missing or empty)."""

    def segments(self, time_s: float, true_state: np.ndarray,
                 estimated_state: np.ndarray) -> np.ndarray | None: ...


@dataclass(frozen=True)
class LoopConfig:
    duration_s: float
    waypoints: np.ndarray  # (K, 2)
    outlines: tuple  # true walls and obstacle outlines (polylines) for clearance
    desired_separation_m: float  # R_b + d_p
    goal_radius_m: float = 5.0
    control_period_s: float = 0.1
    imu_period_s: float = 0.01  # the plant's step and the AHRS period
    gps: GpsConfig = GpsConfig()  # rate (5 Hz) and noise of the RTK fix
    ahrs: AhrsConfig = AhrsConfig()  # noise of the AHRS
    current_ne: tuple = (0.0, 0.0)
    seed: int = 0
    snapshot_times_s: tuple = ()  # instants at which to keep the plan for plots
    outline_removed_at_s: tuple = ()  # per outline: when it leaves the water (None: never)
    obstacles: tuple = ()  # metrics.WatchedObstacle: per-obstacle clearance and detection
    lidar_outages_s: tuple = ()  # (start, end) spans of simulation time with no scan
    feed: FeedConfig = FeedConfig()  # how long the last segments bridge missing scans
    current_field: object = None  # scenarios.world.current.CurrentField; None: current_ne
    vessels: tuple = ()  # scenarios.world.vessels.Vessel: other boats, for the metrics
    walls: tuple = ()  # the true walls alone (polylines): tracks on them are no boats
    target_speed_mps: float = 2.0  # "steady running" for the water metrics: near this speed


@dataclass
class Snapshot:
    time_s: float
    state: np.ndarray
    predicted: np.ndarray | None
    segments: np.ndarray
    tracks: list = field(default_factory=list)  # [x, y, heading, length, width] per track


@dataclass
class RunResult:
    summary: dict
    timing: dict
    snapshots: list
    log_path: Path


class _Timer:
    """Accumulates wall time and this thread's CPU time per component, for 'where the time
    goes' (the CPU time means something on a loaded machine too)."""

    def __init__(self):
        self.total: dict[str, float] = {}
        self.cpu: dict[str, float] = {}

    def add(self, name: str, seconds: float, cpu_s: float | None = None) -> None:
        self.total[name] = self.total.get(name, 0.0) + seconds
        if cpu_s is not None:
            self.cpu[name] = self.cpu.get(name, 0.0) + cpu_s


def run_closed_loop(plant: Plant, controller: Controller, perception: Perception,
                    state0, cfg: LoopConfig, out_dir: Path,
                    progress: Callable[[float, float], None] | None = None,
                    scenario_name: str = "",
                    events: Callable[[float, str], None] | None = None,
                    viz=None) -> RunResult:
    """Run one scenario to the goal, the time limit, or a controller failure. `events(t,
    text)` hears when the controller starts and stops waiting (a blocked way, blindness).
    `viz` (a `scenarios.results.mcap_log.LoopViz`) hears every step for run.mcap and the live
    view; it only reads, so the results are the same without it."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    timer = _Timer()
    path = Polyline(cfg.waypoints)
    goal = np.asarray(cfg.waypoints, float)[-1]
    # the goal is reached within goal_radius_m of it or past its finish line (square to the
    # last leg through it), as ArduPilot's waypoint navigation counts a waypoint passed: a
    # boat kept off the line by another vessel passes it abeam and would otherwise go on
    route = np.asarray(cfg.waypoints, float).reshape(-1, 2)
    finish = _finish_direction(route)
    n_imu = max(1, int(round(cfg.control_period_s / cfg.imu_period_s)))
    gps_every = max(1, int(round(1.0 / (cfg.gps.rate_hz * cfg.imu_period_s))))
    n_steps = int(math.floor(cfg.duration_s / cfg.control_period_s + 1e-9))
    snapshot_steps = {int(round(t / cfg.control_period_s)) for t in cfg.snapshot_times_s}

    gps = GpsSensor(cfg.gps, seed=cfg.seed * 7919 + 1)
    ahrs = AhrsSensor(cfg.ahrs, seed=cfg.seed * 7919 + 2)
    out: PlantOutput = plant.reset(np.asarray(state0, float), cfg.current_ne)
    nav = NavigationFilter(out.state)
    own_estimate = out.estimate is None  # else the plant estimates (an autopilot's EKF)

    command = np.zeros(2)
    rows_t, rows_clear, rows_cmd, rows_xt, solve_s = [], [], [], [], []
    phases: list[tuple] = []  # NMPC (feedback, preparation, step) seconds, fed back
    rows_waiting, rows_speed, rows_xy = [], [], []
    rows_water: list[tuple] = []  # (time, true current N, E, estimated N, E) per step
    field = cfg.current_field
    varying = field is not None and field.varies
    snapshots: list[Snapshot] = []
    status, reached = "time limit", False
    world = _ChangingOutlines(cfg)
    feed = SegmentFeed(cfg.feed)
    watch = metrics.ObstacleWatch(cfg.obstacles)
    rows_width: list[tuple[float, float, float]] = []
    collided = False
    fallback_steps = 0
    elastic_max, elastic_steps = [0.0, 0.0], 0  # the NMPC's soft obstacle rows (h units)
    surge_over_max, surge_over_steps = 0.0, 0  # its plans above their surge ceilings
    restarts = 0  # steps the NMPC solved again from the reference (rows broken too far)
    back_offs, was_backing = 0, False  # times it backed off along its path, held at rest
    waiting_before = ""
    takes = inspect.signature(controller.step).parameters
    takes_blind, takes_vessels = "blind" in takes, "vessels" in takes
    encounters = EncounterWatch(cfg.vessels)
    tracking = TrackingWatch(cfg.vessels, walls=cfg.walls,
                             objects=tuple(o.outline for o in cfg.obstacles))
    perceive = getattr(perception, "perceive", None) or perception.segments
    prepare = getattr(controller, "prepare", None)  # an NMPC's preparation phase
    wall0 = time.perf_counter()
    with RunLog(out_dir / "log.csv", out_dir / "segments.csv") as log:
        imu_k = 0
        for k in range(n_steps):
            t = k * cfg.control_period_s
            est = nav.state if own_estimate else np.asarray(out.estimate, float)
            outlines, contact, canal_width, clearance = world.at(t)
            t0, c0 = time.perf_counter(), time.thread_time()
            found = perceive(t, out.state, est)
            if any(a <= t < b for a, b in cfg.lidar_outages_s):
                found = None  # the scan is lost (a configured outage)
            view = feed.update(t, found, est[:2])
            segs = view.segments
            t1, c1 = time.perf_counter(), time.thread_time()
            extra = {}  # what the controller takes: a controller of the older interface knows
            if takes_blind:  # neither blindness nor other vessels
                extra["blind"] = view.blind
            if takes_vessels:
                extra["vessels"] = view.tracks
            decision = controller.step(t, est, out.actuators.copy(), segs, **extra)
            t2, c2 = time.perf_counter(), time.thread_time()
            timer.add("perception", t1 - t0, c1 - c0)
            timer.add("controller", t2 - t1, c2 - c1)
            estimator_s = decision.stats.get("estimator_s")
            if estimator_s is not None:
                timer.add("water_estimator", estimator_s)  # (part of the controller's time)
            true_current = field.at(out.state[:2]) if field is not None else np.asarray(
                cfg.current_ne, float)
            solve_s.append(t2 - t1)
            if decision.stats.get("feedback_s") is not None:  # the NMPC's two phases
                phases.append((decision.stats["feedback_s"], decision.stats["preparation_s"],
                               decision.stats["nmpc_step_s"], decision.stats["fed_back"],
                               decision.stats.get("set_up_in_preparation", False)))
            if not decision.ok:
                status = f"controller failed: {decision.status}"
                command = np.zeros(2)
            else:
                command = np.clip(np.asarray(decision.command, float).reshape(2), -100, 100)
            if prepare is not None:  # the command is out: the controller's next step
                tp, cp = time.perf_counter(), time.thread_time()  # is prepared off the
                prepare()  # state-to-command path
                timer.add("controller", time.perf_counter() - tp, time.thread_time() - cp)
            prev = rows_cmd[-1] if rows_cmd else np.zeros(2)
            rate = (command - prev) / cfg.control_period_s
            clear = clearance.of(out.state)
            xt = path.cross_track(out.state[:2])
            width = canal_width.at(out.state)
            if cfg.vessels:  # other vessels count for clearance where they are now
                hulls = [v.outline_at(t) for v in cfg.vessels]
                ring = [np.vstack([h, h[:1]]) for h in hulls]
                clear = np.minimum(clear, metrics.clearance(out.state[None, :3], ring)[0])
            vessel_gap = encounters.update(t, out.state, width[2])
            if view.tracks or cfg.vessels:
                tracking.update(t, out.state, view.tracks, cfg.control_period_s)
                log.write_tracks(t, view.tracks, [(v.name, v.pose_at(t)) for v in cfg.vessels])
            watch.update(t, out.state, segs)
            waiting = str(decision.stats.get("waiting", ""))
            fallback_steps += bool(decision.stats.get("fallback", ""))
            restarts += bool(decision.stats.get("restarted", False))
            backing = bool(decision.stats.get("backing_off", False))
            back_offs += backing and not was_backing
            was_backing = backing
            over = decision.stats.get("surge_over")
            if over is not None:
                surge_over_max = max(surge_over_max, over)
                surge_over_steps += over > 0.05
            elastic = decision.stats.get("elastic")
            if elastic is not None:
                elastic_max = [max(a, b) for a, b in zip(elastic_max, elastic)]
                elastic_steps += max(elastic) > 1e-3
            log.write_step(
                t, out.state, est, command, rate, out.actuators, clear, xt,
                (t2 - t1) * 1e3, decision, segs, width, view, true_current,
            )
            if viz is not None:
                tv, cv = time.perf_counter(), time.thread_time()
                viz.step(t, out.state, est, outlines, segs, decision, view, command, rate,
                         out.actuators, clear, xt, (t2 - t1) * 1e3,
                         cloud=getattr(perception, "last_cloud", None),
                         vessels=[(v.name, v.outline_at(t)) for v in cfg.vessels])
                timer.add("viz", time.perf_counter() - tv, time.thread_time() - cv)
            water = decision.stats.get("water")
            if water is not None:
                rows_water.append((t, *true_current, *water.current_ne, out.state[3]))
            why = waiting_kind(waiting)  # "way blocked", "blind", ""
            if events is not None and why != waiting_before:
                events(t, f"waiting: {waiting}" if waiting else "the way is clear: going on")
            waiting_before = why
            rows_waiting.append(bool(waiting))
            rows_speed.append(float(np.hypot(out.state[3], out.state[4])))
            rows_xy.append((float(out.state[0]), float(out.state[1])))
            rows_width.append(width)
            rows_t.append(t)
            rows_clear.append(clear)
            rows_cmd.append(command)
            rows_xt.append(xt)
            if k in snapshot_steps:
                snapshots.append(Snapshot(t, out.state.copy(), decision.predicted, segs, [
                    [*map(float, tr.position), float(tr.heading_rad), float(tr.length_m),
                     float(tr.width_m)] for tr in view.tracks]))
            if not decision.ok:
                break
            if min(clear) <= contact.reach_m and contact.touches(out.state):
                status, collided = f"collision at t = {t:.1f} s", True
                break
            if vessel_gap <= 0.0:
                hit = cfg.vessels[int(np.argmin(encounters.min_distance))].name
                status, collided = f"collision with vessel {hit!r} at t = {t:.1f} s", True
                break
            if varying:
                plant.set_current(true_current)
            try:
                for i in range(n_imu):
                    ta, ca = time.perf_counter(), time.thread_time()
                    out = plant.step(command, cfg.imu_period_s)
                    tb, cb = time.perf_counter(), time.thread_time()
                    timer.add("plant", tb - ta, cb - ca)
                    if not own_estimate:
                        continue
                    sample = ahrs.measure(out.state, out.state_dot)
                    nav.predict(cfg.imu_period_s, sample.accel_body)
                    nav.update_ahrs(sample.heading_rad, sample.yaw_rate_radps)
                    imu_k += 1
                    if imu_k % gps_every == 0:
                        fix = gps.measure(out.state)
                        nav.update_gps(fix.position_ne, fix.velocity_ne)
                        if viz is not None:
                            viz.gps_fix(t + (i + 1) * cfg.imu_period_s, fix.position_ne)
                    timer.add("navigation", time.perf_counter() - tb, time.thread_time() - cb)
            except PlantFailure as exc:  # e.g. a lost MAVLink link: what was logged stays
                status = f"plant failed: {exc}"
                break
            if (np.hypot(*(out.state[:2] - goal)) <= cfg.goal_radius_m
                    or _past_finish(out.state[:2], route, finish)):
                status, reached = "reached goal", True
                break
            if progress is not None:
                progress(t + cfg.control_period_s, cfg.duration_s)
    wall = time.perf_counter() - wall0

    duration = (rows_t[-1] + cfg.control_period_s) if rows_t else 0.0
    summary = {
        "scenario": scenario_name,
        "controller": getattr(controller, "name", type(controller).__name__),
        "seed": cfg.seed,
        "status": status,
        "reached_goal": reached,
        "collision": collided,
        **metrics.track_figures(rows_t, rows_clear, rows_cmd, rows_xt, out.state, goal,
                                cfg.desired_separation_m, cfg.control_period_s),
        "fallback_steps": fallback_steps,
        # how far the NMPC's QPs had to violate their linearised obstacle rows (units of h,
        # about metres per metre of margin; exact-penalty rows only) and on how many steps
        "elastic": {"max_segment_rows": _round(elastic_max[0]),
                    "max_vessel_rows": _round(elastic_max[1]), "steps": elastic_steps,
                    "restarts": restarts, "back_offs": back_offs},
        # how far the NMPC's plans went above their soft surge ceilings (m/s; the steps
        # with more than 0.05 over)
        "surge_over": {"max_mps": _round(surge_over_max), "steps": surge_over_steps},
    }
    episodes = metrics.waiting_episodes(rows_waiting, rows_speed, cfg.control_period_s,
                                        xy=rows_xy)
    summary.update({k: _round(v) for k, v in episodes.items()})
    summary["time_blind_s"] = _round(feed.blind_periods * cfg.control_period_s)
    summary["missing_scans"] = feed.missing_scans
    summary["segments_cleaned"] = dict(feed.dropped_total)
    # separation by place: kept where the canal allows it, the middle where it does not
    summary.update(metrics.separation_figures(rows_clear, rows_width, cfg.desired_separation_m,
                                              cfg.control_period_s))
    if cfg.obstacles:
        summary["obstacles"] = watch.summary()
    if cfg.vessels:
        summary["vessels"] = encounters.summary(cfg.control_period_s)
    if cfg.vessels or tracking.saw_tracks:
        summary["tracking"] = tracking.summary()
    if rows_water:
        summary["water"] = {"mode": getattr(controller, "water", None),
                            **{k: _round(v) if isinstance(v, float) else v
                               for k, v in metrics.water_estimate(
                                   np.array(rows_water), cfg.target_speed_mps).items()}}
    stats = metrics.TimingStats.of(solve_s)
    timing = {
        "controller": summary["controller"],
        "solve_ms": {"mean": stats.mean_ms, "p99": stats.p99_ms, "max": stats.max_ms},
        "wall_time_s": wall,
        "real_time_factor": duration / wall if wall > 0 else None,
        "where_the_time_goes_s": {k: round(v, 4) for k, v in sorted(timer.total.items())},
        "where_the_cpu_goes_s": {k: round(v, 4) for k, v in sorted(timer.cpu.items())},
    }
    if phases:
        for i, key in enumerate(("feedback_latency_ms", "preparation_ms", "nmpc_step_ms")):
            ph = metrics.TimingStats.of([row[i] for row in phases])
            timing[key] = {"mean": ph.mean_ms, "p99": ph.p99_ms, "max": ph.max_ms}
        timing["fed_back_steps"] = int(sum(row[3] for row in phases))
        timing["set_up_in_preparation_steps"] = int(sum(row[4] for row in phases))
    behind = getattr(perception, "time_s", None)  # the LiDAR's own time, maybe on another core
    if behind is not None:
        timing["perception"] = {
            "parallel": bool(getattr(perception, "parallel", False)),
            **{f"{k}_s": round(v, 4) for k, v in sorted(behind.items())},
            "scans": len(getattr(perception, "points_per_scan", ())),
        }
    (out_dir / "snapshots.json").write_text(json.dumps([
        {"time_s": sn.time_s, "state": sn.state.tolist(),
         "predicted": None if sn.predicted is None else np.asarray(sn.predicted).tolist(),
         "segments": np.asarray(sn.segments).tolist(), "tracks": sn.tracks}
        for sn in snapshots
    ]) + "\n")
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out_dir / "timing.json").write_text(json.dumps(timing, indent=2) + "\n")
    return RunResult(summary, timing, snapshots, out_dir / "log.csv")


class _ChangingOutlines:
    """The true outlines present at a time (an obstacle may be removed during the run), with
    the collision test, the canal width and the clearance over them, rebuilt only when the
    set changes."""

    def __init__(self, cfg: LoopConfig):
        self._outlines = tuple(cfg.outlines)
        self._removed = tuple(cfg.outline_removed_at_s) or (None,) * len(self._outlines)
        self._key = None
        self._current = None

    def at(self, time_s: float):
        key = tuple(r is None or time_s < r for r in self._removed)
        if key != self._key:
            present = tuple(o for o, here in zip(self._outlines, key) if here)
            self._key = key
            self._current = (present, metrics.HullContact(present), metrics.CanalWidth(present),
                             metrics.Clearance(present))
        return self._current


_round = metrics.summary_round


def terminal_progress(stream=sys.stderr) -> Callable[[float, float], None]:
    """A one-line progress bar, redrawn at most 5 times a second."""
    last = [0.0]

    def show(t: float, total: float) -> None:
        now = time.perf_counter()
        if now - last[0] < 0.2 and t < total:
            return
        last[0] = now
        frac = min(1.0, t / total) if total > 0 else 1.0
        bar = "#" * int(30 * frac)
        stream.write(f"\r[{bar:<30}] {t:7.1f}/{total:.0f} s sim")
        stream.flush()

    return show


def log_progress(stream=None, every_s: float = 5.0,
                 clock=time.perf_counter) -> Callable[[float, float], None]:
    """A progress line every `every_s` of wall time, for a log rather than a terminal (a CI
    job, a batch script, `| tee`): the share done, the simulated time, the wall time so far
    and the time left at the pace so far."""
    start = clock()
    last = [start]

    def show(t: float, total: float) -> None:
        now = clock()
        done = t >= total
        if now - last[0] < every_s and not done:
            return
        last[0] = now
        frac = min(1.0, t / total) if total > 0 else 1.0
        spent = now - start
        left = spent * (1.0 - frac) / frac if frac > 0 else float("nan")
        out = stream or sys.stderr  # (looked up now: a redirected stderr is the one used)
        out.write(f"run: {100 * frac:3.0f} % ({t:.1f} of {total:.0f} s simulated), "
                  f"{spent:.0f} s so far, about {left:.0f} s left\n")
        out.flush()

    return show


def terminal_events(redraw: bool, stream=sys.stderr) -> Callable[[float, str], None]:
    """Print what the controller starts or stops waiting for, one line each (below the
    progress bar when there is one)."""

    def say(t: float, text: str) -> None:
        stream.write(f"{chr(10) if redraw else ''}t = {t:.1f} s: {text}\n")
        stream.flush()

    return say


def _past_finish(position, pts: np.ndarray, finish) -> bool:
    """The boat is past the finish line of the route `pts` (K, 2) and on its last leg
    (nearer it than any other: a route that doubles back does not end where an earlier leg
    passes behind the goal)."""
    if float(np.dot(position - pts[-1], finish)) <= 0.0:
        return False
    if len(pts) < 3:
        return True
    d = point_segment_distance(np.asarray(position, float).reshape(1, 2), pts[:-1], pts[1:])
    return bool(np.argmin(np.asarray(d).reshape(-1)) == len(pts) - 2)


def _finish_direction(waypoints) -> np.ndarray:
    """The last leg's unit direction (zeros for a route of one point: no finish line)."""
    pts = np.asarray(waypoints, float).reshape(-1, 2)
    if len(pts) < 2:
        return np.zeros(2)
    leg = pts[-1] - pts[-2]
    norm = float(np.hypot(*leg))
    return leg / norm if norm > 0 else np.zeros(2)
