"""Adapters from the controllers in `controller` to the closed loop's `Controller` interface."""

from __future__ import annotations

import time

import numpy as np

from controller.baselines.los_pid import LosPidConfig, LosPidTracker
from controller.geometry import Polyline
from controller.params import BoatParams
from scenarios.loop.closed_loop import Decision


class LosPidController:
    """LOS guidance with PID, tracking the scenario's waypoints directly (no planner)."""

    name = "los-pid"

    def __init__(self, params: BoatParams, waypoints, config: LosPidConfig = LosPidConfig(),
                 control_period_s: float = 0.1):
        self._tracker = LosPidTracker(params, config)
        self._tracker.set_path(waypoints)
        self._dt = control_period_s

    def step(self, time_s, state, actuators, segments, blind=False) -> Decision:
        if time_s == 0.0:
            self._tracker.reset(actuators)
        command = self._tracker.step(state, self._dt)
        return Decision(command=command, segments_used=np.empty((0, 4)))


def _sight_m(scenario) -> float:
    """How far ahead the scenario's perception sees another vessel: the range known walls
    hand vessels over at, or the LiDAR detector's crop."""
    if scenario.perception == "known-walls":
        return float(scenario.known_walls_range_m)
    from controller.perception.detection import DetectionConfig

    return float(DetectionConfig().range_m)


class NmpcController:
    """The paper's NMPC (controller.nmpc.NmpcController) on the scenario's waypoints and d_p.

    `[controller.options]` of the scenario sets `NmpcConfig` fields by name, plus `method`
    (rti | sqp | ipopt) and `water`: what the NMPC knows of the current and the model's error,
    "estimated" (default: `controller.water_estimator` on the state estimate and the
    actuators, as a real boat must), "still" (nothing: the paper's NMPC) or "true" (the
    scenario's current, as from a current meter; `knows_current = true` is its older name).
    The estimator runs in every mode, so its estimate is logged beside the truth.
    """

    name = "nmpc"

    def __init__(self, scenario):
        from dataclasses import fields

        from controller.errors import InputError
        from controller.nmpc.controller import NmpcController as Core
        from controller.nmpc.problem import NmpcConfig
        from controller.water_estimator import WaterEstimator, WaterEstimatorConfig

        options = dict(scenario.controller_options)
        method = options.pop("method", "rti")
        knows = options.pop("knows_current", None)
        water = options.pop("water", None)
        self.water = water or ("estimated" if knows is None else "true" if knows else "still")
        known = {f.name for f in fields(NmpcConfig)} - {"boat", "separation_m"}
        for key in options:
            if key not in known:
                raise InputError(f"{scenario.path or scenario.name}: field 'controller.options.{key}': "
                                 f"unknown NMPC option (known: method, knows_current, {', '.join(sorted(known))})")
        options = {k: tuple(v) if isinstance(v, list) else v for k, v in options.items()}
        options.setdefault("sight_m", _sight_m(scenario))
        config = NmpcConfig(separation_m=scenario.d_p_m, boat=scenario.controller_params, **options)
        self.core = Core(config, method=method)
        self.name = "nmpc" if method == "rti" else f"nmpc-{method}"
        self._waypoints = scenario.waypoints
        self._speed = scenario.target_speed_mps
        self._field = scenario.current_field
        self._prepare = False  # a preparation is due (after a step, until done)
        self.estimator = WaterEstimator(WaterEstimatorConfig(
            period_s=config.control_period_s, boat=scenario.controller_params))

    def step(self, time_s, state, actuators, segments, blind=False, vessels=()) -> Decision:
        from controller.errors import SolverError
        from controller.water_estimator import usable_current

        t0 = time.perf_counter()
        water = self.estimator.update(state, actuators, time_s)
        estimator_s = time.perf_counter() - t0
        if self.water == "estimated":  # each part of the current as far as it is known
            current = usable_current(water, float(np.asarray(state, float)[2]),
                                     self.estimator.config.current_sigma0)
            bias = water.bias
        elif self.water == "true":
            current, bias = self._field.at(np.asarray(state)[:2]), (0.0, 0.0, 0.0)
        else:
            current, bias = (0.0, 0.0), (0.0, 0.0, 0.0)
        self.prepare()  # if the loop did not, after the last command
        try:
            st = self.core.feedback(state, actuators, segments, self._waypoints, self._speed,
                                    current, blind=blind, bias=bias, vessels=vessels)
        except SolverError as exc:
            return Decision(command=np.zeros(2), ok=False, status=str(exc),
                            stats={"water": water, "estimator_s": estimator_s})
        self._prepare = self.core.split  # the next step's preparation is due
        return Decision(
            command=st.command, status=_status(st), predicted=st.states,
            slack_m=st.max_slack_m, segments_used=segments,
            stats={"qp_iterations": st.stats.qp_iterations, "fallback": st.stats.fallback,
                   "segments_dropped": st.stats.segments_dropped, "waiting": st.stats.waiting,
                   "water": water, "estimator_s": estimator_s, "rules": st.stats.rules,
                   "current_used": np.asarray(current, float),
                   "feedback_s": st.stats.time_feedback_s,
                   "preparation_s": st.stats.time_preparation_s,
                   "nmpc_step_s": st.stats.time_total_s, "fed_back": st.stats.fed_back,
                   "set_up_in_preparation": st.stats.set_up_in_preparation,
                   "elastic": (st.stats.elastic_segments, st.stats.elastic_vessels),
                   "restarted": st.stats.restarted, "backing_off": st.stats.backing_off,
                   "surge_over": st.stats.surge_over_mps},
        )

    def prepare(self) -> None:
        """The NMPC's preparation for the next step (`NmpcController.prepare`): for the loop
        to call once the command has gone out, so that the next step's state-in to
        command-out is the feedback alone. A step that finds it not done does it first."""
        if self._prepare:
            self._prepare = False
            self.core.prepare()


def _status(st) -> str:
    """The log's status of an NMPC step: a fallback first, then why it waits, else the QP's."""
    if not st.stats.ok or st.stats.fallback:  # a failed solve (retried from the safe guess)
        return f"fallback:{st.stats.fallback}"
    return f"waiting: {st.stats.waiting}" if st.stats.waiting else st.stats.status


class PlannedLosPid:
    """A planner replanning at `replan_period_s`, tracked by LOS guidance with PID at 10 Hz.

    Baseline 1 (after Villa et al. 2020, as the paper used it): the planner is the NMPC
    itself, iterated to convergence (SQP) since it plans once a second. Baseline 2: the
    lexicographic planner of the paper's Appendix. The tracker never sees the segments.
    The tracked path is the plan followed by the waypoints beyond its end (our choice): a
    plan kept while the planner finds none runs out, and LOS at the end of a path would
    turn the boat around; after the plan, the waypoints are what the boat has to go by.
    """

    def __init__(self, name: str, planner, params, waypoints, target_speed_mps: float,
                 replan_period_s: float = 1.0, control_period_s: float = 0.1):
        self.name = name
        self._plan = planner  # (state, actuators, segments) -> (path (K, 2), ok, status, predicted)
        self._tracker = LosPidTracker(params, LosPidConfig(target_speed_mps=target_speed_mps))
        self._tracker.set_path(waypoints)
        self._waypoints = Polyline(waypoints)
        self._every = max(1, int(round(replan_period_s / control_period_s)))
        self._dt = control_period_s
        self._k = 0
        self._predicted = None
        self._status = "ok"

    def step(self, time_s, state, actuators, segments, blind=False) -> Decision:
        if self._k == 0:
            self._tracker.reset(actuators)
        if self._k % self._every == 0:
            path, ok, status, predicted = self._plan(state, actuators, segments, blind)
            self._status = status
            if ok and len(path) >= 2:
                self._tracker.set_path(self._then_waypoints(path), state)
                self._predicted = predicted
        self._k += 1
        command = self._tracker.step(state, self._dt)
        return Decision(command=command, status=self._status, predicted=self._predicted,
                        segments_used=segments)


    def _then_waypoints(self, path) -> np.ndarray:
        """The plan, then the waypoints that lie beyond its end along the waypoint path."""
        wp = self._waypoints
        s_start = wp.project(path[0])[0]
        s_end = wp.project(path[-1], s_min=s_start)[0]
        rest = wp.points[1:][wp.cumulative[1:] > s_end + 1.0]
        return np.vstack([np.asarray(path, float).reshape(-1, 2), rest])


def nmpc_planned_los_pid(scenario) -> PlannedLosPid:
    """Baseline 1: the NMPC as a 1 Hz planner, LOS-PID tracking its predicted path."""
    from controller.errors import SolverError
    from controller.nmpc.problem import NmpcConfig
    from controller.nmpc.controller import NmpcController as Core

    core = Core(NmpcConfig(separation_m=scenario.d_p_m, boat=scenario.controller_params,
                           control_period_s=1.0), method="sqp")

    def plan(state, actuators, segments, blind):
        try:
            st = core.step(state, actuators, segments, scenario.waypoints,
                           scenario.target_speed_mps, elapsed_s=1.0, blind=blind)
        except SolverError as exc:  # keep tracking the last plan; the planner recovers next time
            core.reset()
            return None, False, f"planner failed: {exc}", None
        return st.states[:, :2], True, st.stats.status, st.states

    return PlannedLosPid("los-pid", plan, scenario.controller_params, scenario.waypoints,
                         scenario.target_speed_mps)


def lexicographic_los_pid(scenario) -> PlannedLosPid:
    """Baseline 2: the lexicographic planner at 1 Hz, LOS-PID tracking its path."""
    from controller.baselines.lexicographic import LexicographicConfig, LexicographicPlanner

    planner = LexicographicPlanner(scenario.waypoints,
                                   LexicographicConfig(separation_m=scenario.d_p_m))

    def plan(state, actuators, segments, blind):  # the Appendix's planner knows no blindness
        p = planner.plan(state[:3], segments)
        return p.path, True, p.status, p.states

    return PlannedLosPid("lexicographic", plan, scenario.controller_params, scenario.waypoints,
                         scenario.target_speed_mps)
