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
