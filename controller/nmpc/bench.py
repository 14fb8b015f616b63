"""A small closed loop for measuring and testing the NMPC: canals as wall polylines, the
segments a perfect detector would report (the paper's simulation: walls within 50 m known),
and the smooth model as the plant. Scenario runs with LiDAR and the FMU live in `scenarios`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import SolverError
from ..geometry import Segment, distance_to_polylines
from ..model import SMOOTH, plant_step_function
from .controller import NmpcController, NmpcStep
from .segment_slots import distance_to_segments


@dataclass(frozen=True)
class Canal:
    """Walls as polylines (metres, NED) and the waypoints a boat should follow."""

    walls: tuple[np.ndarray, ...]
    waypoints: np.ndarray
    name: str = "canal"

    def segments(self) -> np.ndarray:
        """Every wall piece as (x_c, y_c, theta, length) rows."""
        rows = [Segment.from_endpoints(a, b).as_array()
                for wall in self.walls for a, b in zip(wall[:-1], wall[1:])]
        return np.array(rows)


def _offset(centre: np.ndarray, half_width: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Port and starboard walls at half_width either side of a centre polyline."""
    d = np.gradient(centre, axis=0)
    d /= np.hypot(d[:, 0], d[:, 1])[:, None]
    normal = np.column_stack([-d[:, 1], d[:, 0]])  # to starboard of the heading (NED)
    return centre - half_width[:, None] * normal, centre + half_width[:, None] * normal


def straight_canal(width_m: float = 20.0, length_m: float = 400.0,
                   waypoint_offset_m: float = 0.0, piece_m: float = 20.0) -> Canal:
    """A canal heading north from x = -50 m, centred on y = 0, its walls in pieces of
    `piece_m` (as a detector reports them); waypoints offset to the east."""
    x = np.arange(-50.0, length_m + piece_m, piece_m)
    port = np.column_stack([x, np.full(len(x), -width_m / 2)])
    stbd = np.column_stack([x, np.full(len(x), width_m / 2)])
    wp = np.column_stack([[0.0, length_m - 20.0], [waypoint_offset_m] * 2])
    return Canal((port, stbd), wp, f"straight {width_m:g} m")


def open_water(length_m: float = 1000.0) -> Canal:
    return Canal((), np.array([[0.0, 0.0], [length_m, 0.0]]), "open water")


def bend_canal(width_m: float = 16.0, narrow_m: float = 9.0) -> Canal:
    """North for 40 m, a 90 deg bend to starboard (radius 30 m), then east with a stretch
    `narrow_m` wide from 40 to 70 m along the east leg (tapers of 10 m)."""
    straight_n = np.column_stack([np.linspace(-20.0, 40.0, 5), np.zeros(5)])
    a = np.radians(np.arange(7.5, 90.0, 7.5))
    arc = np.column_stack([40.0 + 30.0 * np.sin(a), 30.0 - 30.0 * np.cos(a)])
    y_east = np.array([30.0, 45.0, 60.0, 70.0, 85.0, 100.0, 110.0, 125.0, 150.0])
    east = np.column_stack([np.full(len(y_east), 70.0), y_east])
    centre = np.vstack([straight_n, arc, east])
    half = np.full(len(centre), width_m / 2)
    along_east = centre[:, 1] - 30.0
    east_leg = np.arange(len(centre)) >= len(straight_n) + len(arc)
    narrow = east_leg & (along_east >= 40.0) & (along_east <= 70.0)
    half[narrow] = narrow_m / 2
    port, stbd = _offset(centre, half)
    return Canal((port, stbd), centre[1:-1].copy(), f"bend {width_m:g} m, narrow {narrow_m:g} m")


def visible_segments(all_segments: np.ndarray, position, range_m: float = 50.0) -> np.ndarray:
    """The segments with a point within `range_m` of the boat (the perfect detector)."""
    if len(all_segments) == 0:
        return np.zeros((0, 4))
    return all_segments[distance_to_segments(np.asarray(position, float)[:2], all_segments)
                        <= range_m]


def hull_centres(state: np.ndarray, offsets=(2.0, -2.0)) -> np.ndarray:
    """The two hull circle centres (2, 2) of state [x, y, psi, ...]."""
    c, s = np.cos(state[2]), np.sin(state[2])
    return np.array([[state[0] + d * c, state[1] + d * s] for d in offsets])


@dataclass
class Run:
    """A closed-loop run: per control step, the plant state and what the controller did."""

    states: np.ndarray  # (T+1, 6)
    actuators: np.ndarray  # (T+1, 2)
    steps: list[NmpcStep] = field(default_factory=list)
    clearance_m: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (T+1,)
    failure: str = ""

    @property
    def step_times_s(self) -> np.ndarray:
        return np.array([s.stats.time_total_s for s in self.steps])


@dataclass(frozen=True)
class BenchVessel:
    """Another vessel at constant velocity, in the form of a perception track."""

    id: int
    start: tuple
    velocity: tuple
    length_m: float = 12.0
    width_m: float = 3.5

    def at(self, time_s: float):
        """Its track at `time_s`: position, velocity, heading and a small covariance."""
        from types import SimpleNamespace

        v = np.asarray(self.velocity, float)
        return SimpleNamespace(
            id=self.id, position=np.asarray(self.start, float) + time_s * v, velocity=v,
            heading_rad=float(np.arctan2(v[1], v[0])) if np.hypot(*v) > 0 else 0.0,
            length_m=self.length_m, width_m=self.width_m,
            covariance=np.diag([0.01, 0.01, 0.001, 0.001]))


def closed_loop(controller: NmpcController, canal: Canal, x0, actuators0, steps: int,
                speed_mps: float = 2.0, current=(0.0, 0.0), plant_substeps: int = 2,
                vessels=(), record: list | None = None, scan_ahead: bool = False) -> Run:
    """Run the controller every control period on the smooth model (actuator rate limits
    on), with other `vessels` (BenchVessel) if given. Stops early, with `failure` set, if the
    controller raises SolverError. `record`: a list that gets, per step, the CPU seconds of
    the whole controller step and what its OCP was given (x_init, parameters, reference,
    warm start), for a peer solver to be handed the same (`acados_peer`). `scan_ahead`: the
    perception of a real loop, where a scan is processed while the boat moves: the segments
    and tracks seen at one step are handed to the controller's preparation right after its
    command (`prepare(segments=..., vessels=...)`) and are the next step's, so the feedback
    only embeds the new state; without it they come with the state (and the feedback sets
    the step up whenever they changed)."""
    cfg = controller.config
    plant = plant_step_function(SMOOTH)
    p = cfg.boat.as_vector()
    rate_max = np.array([cfg.dnT_max, cfg.dnS_max])
    h = cfg.control_period_s / plant_substeps
    all_segments = canal.segments() if canal.walls else np.zeros((0, 4))
    x = np.asarray(x0, float).copy()
    act = np.asarray(actuators0, float).copy()
    states, acts, out = [x.copy()], [act.copy()], []
    failure = ""
    seen = None  # with scan_ahead: the last step's segments and tracks
    for k in range(steps):
        scan = (visible_segments(all_segments, x, cfg.segment_range_m),
                [v.at(k * cfg.control_period_s) for v in vessels])
        segs, tracks = seen if scan_ahead and seen is not None else scan
        cpu0 = time.thread_time()
        try:
            if scan_ahead:
                step = controller.feedback(x, act, segs, canal.waypoints, speed_mps, current,
                                           vessels=tracks)
                seen = scan
                controller.prepare(segments=scan[0], vessels=scan[1])
            else:
                step = controller.step(x, act, segs, canal.waypoints, speed_mps, current,
                                       vessels=tracks)
        except SolverError as exc:
            failure = str(exc)
            break
        if record is not None:
            cpu = time.thread_time() - cpu0
            params, w_ref, guess = controller.last_qp_inputs
            record.append((cpu, np.concatenate([x, act]), params.copy(), w_ref.copy(),
                           None if guess is None else guess.copy()))
        out.append(step)
        for _ in range(plant_substeps):
            x_next, act_next, _ = plant(x, act, step.command, p, current, rate_max, h)
            x, act = np.asarray(x_next).ravel(), np.asarray(act_next).ravel()
        states.append(x.copy())
        acts.append(act.copy())
    states_arr = np.array(states)
    if canal.walls:
        centres = np.array([hull_centres(s, cfg.hull_offsets_m) for s in states_arr])
        d = distance_to_polylines(centres.reshape(-1, 2), canal.walls).reshape(-1, 2)
        clearance = d.min(axis=1)
    else:
        clearance = np.full(len(states_arr), np.inf)
    return Run(states_arr, np.array(acts), out, clearance, failure)
