"""The boat's outputs one communication step ahead, extrapolated from the last two samples.

A co-simulation master (libcosim's fixed-step algorithm among them) hands an FMU's outputs to
the others only after the step: a command computed from the boat's state at t reaches the
boat at t + h. The navigation FMU therefore works one step ahead, on the boat's outputs at
t + h extrapolated from those at t and t - h: second order for the motion (Adams-Bashforth
on its derivatives), linear for the accelerations, and for the actuators their rate-limited
move toward the command held over the step, at the rate they were last seen moving. Its
error is of order h^2 (h^3 for the motion), where the master's delay would be of order h.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BoatSample:
    """The boat FMU's outputs at one instant."""

    state: np.ndarray  # [x, y, psi, u, v, r]
    accel: np.ndarray  # [u_dot, v_dot, r_dot] body frame
    actuators: np.ndarray  # [nT, nS] actual, percent

    def state_dot(self) -> np.ndarray:
        """d/dt [x, y, psi, u, v, r]."""
        psi, u, v, r = self.state[2:6]
        c, s = math.cos(psi), math.sin(psi)
        return np.array([c * u - s * v, s * u + c * v, r, *self.accel])


def ahead(now: BoatSample, before: BoatSample | None, command, step_s: float) -> BoatSample:
    """The sample at now + step_s; `before` is the one at now - step_s (None at the start);
    `command` [nT, nS] is what the actuators are driven toward over the step."""
    f = now.state_dot()
    if before is None:
        state = now.state + step_s * f
        accel = now.accel
        rate = np.zeros(2)
    else:
        state = now.state + step_s * (1.5 * f - 0.5 * before.state_dot())
        accel = 2.0 * now.accel - before.accel
        rate = np.abs(now.actuators - before.actuators) / step_s
    move = np.clip(np.asarray(command, float) - now.actuators, -rate * step_s, rate * step_s)
    return BoatSample(state, accel, now.actuators + move)
