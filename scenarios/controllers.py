"""Adapters from the controllers in `controller` to the closed loop's `Controller` interface."""

from __future__ import annotations

import numpy as np

from controller.baselines.los_pid import LosPidConfig, LosPidTracker
from controller.params import BoatParams
from scenarios.closed_loop import Decision


class LosPidController:
    """LOS guidance with PID, tracking the scenario's waypoints directly (no planner)."""

    name = "los-pid"

    def __init__(self, params: BoatParams, waypoints, config: LosPidConfig = LosPidConfig(),
                 control_period_s: float = 0.1):
        self._tracker = LosPidTracker(params, config)
        self._tracker.set_path(waypoints)
        self._dt = control_period_s

    def step(self, time_s, state, actuators, segments) -> Decision:
        if time_s == 0.0:
            self._tracker.reset(actuators)
        command = self._tracker.step(state, self._dt)
        return Decision(command=command, segments_used=np.empty((0, 4)))


class NmpcController:
    """The paper's NMPC (controller.nmpc_controller) on the scenario's waypoints and d_p.

    `[controller.options]` of the scenario sets `NmpcConfig` fields by name, plus `method`
    (rti | sqp | ipopt) and `knows_current` (default false: the boat does not know the water
    current; it feels it through the estimated state, as a real one would).
    """

    name = "nmpc"

    def __init__(self, scenario):
        from dataclasses import fields

        from controller.errors import InputError
        from controller.nmpc import NmpcConfig
        from controller.nmpc_controller import NmpcController as Core

        options = dict(scenario.controller_options)
        method = options.pop("method", "rti")
        self._knows_current = bool(options.pop("knows_current", False))
        known = {f.name for f in fields(NmpcConfig)} - {"boat", "separation_m"}
        for key in options:
            if key not in known:
                raise InputError(f"{scenario.path or scenario.name}: field 'controller.options.{key}': "
                                 f"unknown NMPC option (known: method, knows_current, {', '.join(sorted(known))})")
        options = {k: tuple(v) if isinstance(v, list) else v for k, v in options.items()}
        config = NmpcConfig(separation_m=scenario.d_p_m, boat=scenario.controller_params, **options)
        self.core = Core(config, method=method)
        self.name = "nmpc" if method == "rti" else f"nmpc-{method}"
        self._waypoints = scenario.waypoints
        self._speed = scenario.target_speed_mps
        self._current = scenario.current_ne if self._knows_current else (0.0, 0.0)

    def step(self, time_s, state, actuators, segments) -> Decision:
        from controller.errors import SolverError

        try:
            st = self.core.step(state, actuators, segments, self._waypoints, self._speed,
                                self._current)
        except SolverError as exc:
            return Decision(command=np.zeros(2), ok=False, status=str(exc))
        return Decision(
            command=st.command, status=st.stats.status if st.stats.ok else f"fallback:{st.stats.fallback}",
            predicted=st.states, slack_m=st.max_slack_m, segments_used=segments,
            stats={"qp_iterations": st.stats.qp_iterations, "fallback": st.stats.fallback},
        )
