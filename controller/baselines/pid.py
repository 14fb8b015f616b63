"""A PID with output saturation, a rate limit and conditional-integration anti-windup."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PidGains:
    kp: float
    ki: float = 0.0
    kd: float = 0.0
    out_min: float = -100.0
    out_max: float = 100.0
    rate_max: float = 0.0  # output units per second; 0 = no limit
    derivative_filter_s: float = 0.0  # time constant of the first-order filter on the D term


class Pid:
    """u = kp e + ki integral(e) - kd d(measurement)/dt (derivative on the measurement).

    The measured rate passes a first-order low-pass filter (`derivative_filter_s`) so that
    sensor noise is not amplified into the command, as in any practical PID.

    The output moves at most `rate_max` per second. The integrator stops while the output
    is held by a bound or by the rate limit in the direction of the error, so neither a
    long saturation nor a slow actuator winds it up.
    """

    def __init__(self, gains: PidGains, output0: float = 0.0):
        self.gains = gains
        self.integral = 0.0
        self.output = float(output0)
        self.rate = 0.0

    def reset(self, output0: float = 0.0) -> None:
        self.integral = 0.0
        self.output = float(output0)
        self.rate = 0.0

    def step(self, error: float, dt: float, measurement_rate: float = 0.0,
             feedforward: float = 0.0) -> float:
        g = self.gains
        if g.derivative_filter_s > 0:
            self.rate += (measurement_rate - self.rate) * dt / (g.derivative_filter_s + dt)
        else:
            self.rate = measurement_rate
        unsat = feedforward + g.kp * error + g.ki * (self.integral + error * dt) - g.kd * self.rate
        out = float(np.clip(unsat, g.out_min, g.out_max))
        if g.rate_max > 0:
            step = g.rate_max * dt
            out = float(np.clip(out, self.output - step, self.output + step))
        # Integrate only while the output is free, or while the error pulls it off its limit.
        if out == unsat or np.sign(error) != np.sign(unsat - out):
            self.integral += error * dt
        self.output = out
        return out
