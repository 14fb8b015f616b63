"""The plant interface of the closed loop, and a plant that integrates the model in Python.

A plant takes throttle and steering commands and reports the true state; the loop never
knows whether it drives the boat FMU through fmpy, the Python model, or (from `bridge`) a
MAVLink autopilot. Time is simulation time in seconds from the scenario start.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from controller.errors import CanalnavError
from controller.params import BoatParams


class PlantFailure(CanalnavError):
    """The plant cannot go on (e.g. its MAVLink link is lost): the run ends with this reason."""


@dataclass(frozen=True)
class ActuatorLimits:
    """Rates at which the real throttle and steering move (%/s); 0 switches a limit off."""

    dnT_max: float = 10.0
    dnS_max: float = 40.0


@dataclass(frozen=True)
class PlantOutput:
    time_s: float
    state: np.ndarray  # [x, y, psi, u, v, r] true
    state_dot: np.ndarray  # time derivative of the state (body accelerations in [3:6])
    actuators: np.ndarray  # [nT, nS] after the rate limits, percent
    estimate: np.ndarray | None = None  # the plant's own state estimate (e.g. an autopilot's
    # EKF over MAVLink); None: the closed loop estimates the state from its simulated sensors


class Plant(Protocol):
    """What the closed loop needs of a boat."""

    def set_current(self, current_ne) -> None:
        """The current (north, east, m/s) from now on (it may change along the canal)."""
        self._current = np.asarray(current_ne, float)

    def reset(self, state0, current_ne=(0.0, 0.0)) -> PlantOutput: ...

    def step(self, command, dt: float) -> PlantOutput: ...

    def close(self) -> None: ...

    # optional: `set_current(current_ne)` for a current that changes along the canal


class ModelPlant:
    """The exact model stepped by CasADi in Python: a reference plant for tests and checks."""

    name = "python-model"

    def __init__(self, params: BoatParams, limits: ActuatorLimits = ActuatorLimits(),
                 internal_step_s: float = 0.01):
        from controller.model import ode_function, plant_step_function

        self._step = plant_step_function()
        self._ode = ode_function()
        self._p = params.as_vector()
        self._rates = np.array([limits.dnT_max, limits.dnS_max], float)
        self._h = internal_step_s
        self._current = np.zeros(2)
        self._x = np.zeros(6)
        self._act = np.zeros(2)
        self._t = 0.0

    def reset(self, state0, current_ne=(0.0, 0.0)) -> PlantOutput:
        self._x = np.asarray(state0, float).copy()
        self._act = np.zeros(2)
        self._current = np.asarray(current_ne, float)
        self._t = 0.0
        return self._output()

    def step(self, command, dt: float) -> PlantOutput:
        n = max(1, int(round(dt / self._h)))
        h = dt / n
        cmd = np.clip(np.asarray(command, float), -100.0, 100.0)
        for _ in range(n):
            x, act, _ = self._step(self._x, self._act, cmd, self._p, self._current,
                                   self._rates, h)
            self._x, self._act = np.asarray(x).ravel(), np.asarray(act).ravel()
        self._t += dt
        return self._output()

    def _output(self) -> PlantOutput:
        """Outputs at the current time: the derivative is taken at the current state."""
        xdot = np.asarray(self._ode(self._x, self._act, self._p, self._current)).ravel()
        return PlantOutput(self._t, self._x.copy(), xdot, self._act.copy())

    def close(self) -> None:
        pass
