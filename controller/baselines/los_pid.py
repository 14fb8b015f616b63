"""Baseline 1's tracker (after Villa et al. 2020): LOS guidance with PID heading and speed.

The path is a polyline: the scenario's waypoints, or a planner's output replaced at its own
rate. At each 0.1 s step: project the boat on the path by a forward search from the previous
progress, steer the course toward the point a lookahead further along the path (Fossen's
lookahead law, generalised to a curved path), compute the heading that gives it, and let two PIDs turn the
heading and speed errors into steering and throttle. Both commands move no faster than the
actuators can (10 %/s, 40 %/s), as every controller in the comparison must.

Sign: nS > 0 turns the boat to port (negative yaw rate), so steering is minus the PID output.
Gains (not published): chosen from the identified model's yaw response at 2 m/s
(about -0.0014 rad/s per % of steering, yaw time constant m33/|N_r| ~ 0.9 s), giving a
heading loop with a natural frequency near 0.7 rad/s and damping near 0.8.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..geometry import Polyline, wrap_angle
from ..params import BoatParams
from .los import heading_from_course, lookahead_course
from .pid import Pid, PidGains


@dataclass(frozen=True)
class LosPidConfig:
    target_speed_mps: float = 2.0
    lookahead_m: float = 12.0  # ~1.5 boat lengths
    heading: PidGains = field(default_factory=lambda: PidGains(
        kp=300.0, ki=5.0, kd=120.0, out_min=-100.0, out_max=100.0, rate_max=40.0,
        derivative_filter_s=0.3))
    speed: PidGains = field(default_factory=lambda: PidGains(
        kp=25.0, ki=3.0, kd=0.0, out_min=-100.0, out_max=100.0, rate_max=10.0))


def steady_throttle(params: BoatParams, speed_mps: float) -> float:
    """Throttle (%) that holds `speed_mps` straight ahead in still water (surge balance)."""
    drag = -params.Xu * speed_mps - params.Xuu * speed_mps * abs(speed_mps)
    return float(np.sign(drag) * np.sqrt(abs(drag) / params.c_eff))


class LosPidTracker:
    """Tracks a polyline with LOS guidance, a heading PID and a speed PID."""

    def __init__(self, params: BoatParams, config: LosPidConfig = LosPidConfig()):
        self.params = params
        self.config = config
        self._heading = Pid(config.heading)
        self._speed = Pid(config.speed)
        self._path: Polyline | None = None
        self._progress = 0.0

    def reset(self, actuators=(0.0, 0.0)) -> None:
        self._speed.reset(actuators[0])
        self._heading.reset(-actuators[1])
        self._progress = 0.0

    def set_path(self, points, state=None) -> None:
        """Follow a new path; progress restarts at the projection of the boat on it."""
        pts = np.asarray(points, float).reshape(-1, 2)
        if len(pts) < 2 or not np.all(np.isfinite(pts)):
            raise InputError(f"LOS path needs at least two finite points, got {len(pts)}")
        keep = np.concatenate([[True], np.hypot(*np.diff(pts, axis=0).T) > 1e-6])
        self._path = Polyline(pts[keep])
        self._progress = 0.0 if state is None else self._path.project(state[:2])[0]

    @property
    def progress_m(self) -> float:
        return self._progress

    def step(self, state, dt: float) -> np.ndarray:
        """[nT, nS] (percent) for the estimated state [x, y, psi, u, v, r]."""
        if self._path is None:
            raise InputError("LOS-PID: no path set")
        x = np.asarray(state, float)
        s, _, _, _ = self._path.project(x[:2], s_min=self._progress)
        self._progress = s
        course = lookahead_course(x[:2], self._path, s, self.config.lookahead_m)
        psi_d = heading_from_course(course, x[3], x[4])
        e_psi = float(wrap_angle(psi_d - x[2]))
        steer_pid = self._heading.step(e_psi, dt, measurement_rate=x[5])
        u_d = self.config.target_speed_mps
        throttle = self._speed.step(u_d - x[3], dt,
                                    feedforward=steady_throttle(self.params, u_d))
        return np.array([throttle, -steer_pid])
