"""canalnav's navigation stack as one box fed the boat's true motion: what the navigation FMU runs.

It repeats `scenarios.loop.closed_loop` around the plant, in the same order and with the same
seeds: every IMU period (0.01 s) the simulated AHRS, and GPS at its rate, into the navigation
filter; every control period (0.1 s) perception, the segment feed and the controller on the
estimate. A master that feeds it the boat's outputs at each IMU instant closes the loop of
`canalnav run` with the controller, sensors and filter of `canalnav run`.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass, replace

import numpy as np

from controller.errors import InputError
from controller.geometry import Polyline
from controller.navigation import NavigationFilter
from controller.perception.feed import SegmentFeed
from scenarios.loop.closed_loop import Decision
from scenarios.loop.runner import loop_config, make_controller, make_perception
from scenarios.results import metrics
from scenarios.scenario_file import Scenario
from scenarios.sensors.gps_ahrs import AhrsSensor, GpsSensor

STATUS_CODES = {"ok": 0, "waiting": 1, "fallback": 2, "failed": 3}
"""The navigation FMU's integer `status` output: what the controller did this period."""


def status_code(decision: Decision) -> int:
    """The `status` output for a decision (STATUS_CODES)."""
    if not decision.ok:
        return STATUS_CODES["failed"]
    if decision.stats.get("fallback"):
        return STATUS_CODES["fallback"]
    if decision.stats.get("waiting"):
        return STATUS_CODES["waiting"]
    return STATUS_CODES["ok"]


@dataclass
class Period:
    """What the stack decided at one control instant, as the FMU outputs and logs it."""

    time_s: float
    command: np.ndarray  # [nT, nS] percent, clipped to [-100, 100]; zeros after a failure
    status: int  # STATUS_CODES
    reason: str  # the controller's own status text (why it failed, when it did)
    slack_m: float
    clearance_m: float  # least hull-circle distance to the segments the controller saw
    cross_track_m: float  # the estimate's distance from the waypoint path
    estimate: np.ndarray  # [x, y, psi, u, v, r] the controller was given
    segments: int


class NavigationStack:
    """Sensors, navigation filter, perception and controller of a scenario, on sim time.

    `sense` takes one IMU period's true motion, `control` one control period's decision; a
    caller runs `sense` then `control` at a control instant, as the closed loop does.
    """

    def __init__(self, scenario: Scenario, controller: str | None = None,
                 seed: int | None = None):
        seed = scenario.seed if seed is None else int(seed)
        if seed != scenario.seed:
            scenario = replace(scenario, seed=seed)
        if scenario.current_profile is not None:
            raise InputError(f"{scenario.path or scenario.name}: field 'current.profile': a "
                             f"current that changes along the canal needs `canalnav run`; the "
                             f"co-simulation's boat takes one current")
        self.scenario = scenario
        self.cfg = loop_config(scenario, seed)
        self.controller = make_controller(scenario, controller)
        self.perception = make_perception(scenario, parallel=False)
        self._perceive = (getattr(self.perception, "perceive", None)
                          or self.perception.segments)
        takes = inspect.signature(self.controller.step).parameters
        self._takes_blind, self._takes_vessels = "blind" in takes, "vessels" in takes
        self._prepare = getattr(self.controller, "prepare", None)
        self._gps = GpsSensor(self.cfg.gps, seed=seed * 7919 + 1)
        self._ahrs = AhrsSensor(self.cfg.ahrs, seed=seed * 7919 + 2)
        self._gps_every = max(1, int(round(1.0 / (self.cfg.gps.rate_hz * self.imu_period_s))))
        self._feed = SegmentFeed(self.cfg.feed)
        self._path = Polyline(self.cfg.waypoints)
        self._nav: NavigationFilter | None = None
        self._imu_k = 0
        self.failed: str | None = None  # why the controller stopped, once it has

    @property
    def imu_period_s(self) -> float:
        return self.cfg.imu_period_s

    @property
    def control_period_s(self) -> float:
        return self.cfg.control_period_s

    def start(self, true_state) -> None:
        """The filter starts at the boat's state at t = 0, as the closed loop's does."""
        self._nav = NavigationFilter(np.asarray(true_state, float))
        self._imu_k = 0

    def sense(self, true_state, state_dot) -> None:
        """One IMU period ended at this state: AHRS into the filter, and GPS at its rate.
        `state_dot` is the state's time derivative (body accelerations in [3:6])."""
        state, xdot = np.asarray(true_state, float), np.asarray(state_dot, float)
        sample = self._ahrs.measure(state, xdot)
        self._nav.predict(self.imu_period_s, sample.accel_body)
        self._nav.update_ahrs(sample.heading_rad, sample.yaw_rate_radps)
        self._imu_k += 1
        if self._imu_k % self._gps_every == 0:
            fix = self._gps.measure(state)
            self._nav.update_gps(fix.position_ne, fix.velocity_ne)

    def control(self, time_s: float, true_state, actuators) -> Period:
        """The controller's decision at a control instant on the filter's estimate; after a
        failure the command stays zero and the reason stays in `failed`."""
        est = self._nav.state.copy()
        if self.failed is not None:
            return Period(time_s, np.zeros(2), STATUS_CODES["failed"], self.failed, 0.0,
                          math.inf, self._cross_track(est), est, 0)
        found = self._perceive(time_s, np.asarray(true_state, float), est)
        if any(a <= time_s < b for a, b in self.cfg.lidar_outages_s):
            found = None
        view = self._feed.update(time_s, found, est[:2])
        extra = {}
        if self._takes_blind:
            extra["blind"] = view.blind
        if self._takes_vessels:
            extra["vessels"] = view.tracks
        decision = self.controller.step(time_s, est, np.asarray(actuators, float).copy(),
                                        view.segments, **extra)
        if decision.ok:
            command = np.clip(np.asarray(decision.command, float).reshape(2), -100, 100)
            if self._prepare is not None:
                self._prepare()
        else:
            command = np.zeros(2)
            self.failed = f"controller failed at t = {time_s:.1f} s: {decision.status}"
        return Period(time_s, command, status_code(decision), str(decision.status),
                      float(decision.slack_m), self._clearance(est, view.segments),
                      self._cross_track(est), est, len(view.segments))

    def _clearance(self, est, segments) -> float:
        segs = np.asarray(segments, float).reshape(-1, 4)
        if not len(segs):
            return math.inf
        half = 0.5 * segs[:, 3:4] * np.column_stack([np.cos(segs[:, 2]), np.sin(segs[:, 2])])
        lines = [np.array([c - h, c + h]) for c, h in zip(segs[:, :2], half)]
        return float(metrics.clearance(est[None, :3], lines)[0].min())

    def _cross_track(self, est) -> float:
        return float(self._path.cross_track(est[:2]))

    def close(self) -> None:
        close = getattr(self.perception, "close", None)
        if close is not None:
            close()
