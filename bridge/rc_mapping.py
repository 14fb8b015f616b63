"""Throttle and steering in percent <-> RC PWM, with ArduPilot's calibration and sense.

Rover reads both sticks as centred inputs (`RC_Channel` of type angle): trim is zero, the
dead zone around trim reads zero, and each side scales linearly to its end (MIN or MAX).
Throttle below trim is reverse. Steering above trim turns to starboard; in our model
`nS > 0` turns to port, so `nS > 0` is PWM below trim. `RCn_REVERSED` flips a channel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class RcCalibration:
    """One RC channel's calibration, as the RCn_* parameters give it (microseconds)."""

    channel: int
    min: float = 1100.0
    max: float = 1900.0
    trim: float = 1500.0
    dz: float = 0.0
    reversed: bool = False

    def __post_init__(self):
        if not self.min < self.trim < self.max:
            raise ValueError(f"RC{self.channel}: need MIN < TRIM < MAX, got "
                             f"{self.min:g} / {self.trim:g} / {self.max:g}")
        if not 0 <= self.dz < min(self.trim - self.min, self.max - self.trim):
            raise ValueError(f"RC{self.channel}_DZ = {self.dz:g} leaves no travel")

    @classmethod
    def from_params(cls, channel: int, params: dict) -> "RcCalibration":
        """From a parameter table (name -> value), defaults where a name is missing."""
        p = lambda k, d: float(params.get(f"RC{channel}_{k}", d))  # noqa: E731
        return cls(channel, p("MIN", 1100), p("MAX", 1900), p("TRIM", 1500), p("DZ", 0),
                   bool(p("REVERSED", 0)))

    def to_pwm(self, percent: float) -> int:
        """Percent of travel in [-100, 100] (positive: above trim unless reversed) to PWM."""
        if not math.isfinite(percent):
            raise ValueError(f"RC{self.channel}: command {percent!r} is not a number")
        v = max(-100.0, min(100.0, float(percent))) / 100.0
        if self.reversed:
            v = -v
        if v > 0:
            pwm = self.trim + self.dz + v * (self.max - self.trim - self.dz)
        elif v < 0:
            pwm = self.trim - self.dz + v * (self.trim - self.dz - self.min)
        else:
            pwm = self.trim
        return int(round(pwm))

    def to_percent(self, pwm: float) -> float:
        """PWM to percent of travel as the autopilot reads it (dead zone reads 0)."""
        pwm = max(self.min, min(self.max, float(pwm)))
        if pwm > self.trim + self.dz:
            v = (pwm - self.trim - self.dz) / (self.max - self.trim - self.dz)
        elif pwm < self.trim - self.dz:
            v = (pwm - self.trim + self.dz) / (self.trim - self.dz - self.min)
        else:
            v = 0.0
        return 100.0 * (-v if self.reversed else v)


@dataclass(frozen=True)
class RcMapping:
    """Which channels steer and throttle (RCMAP_ROLL, RCMAP_THROTTLE) and their calibration."""

    steering: RcCalibration
    throttle: RcCalibration

    @classmethod
    def from_params(cls, params: dict) -> "RcMapping":
        steer = int(params.get("RCMAP_ROLL", 1))
        throttle = int(params.get("RCMAP_THROTTLE", 3))
        for name, ch in (("RCMAP_ROLL", steer), ("RCMAP_THROTTLE", throttle)):
            if not 1 <= ch <= 16:
                raise ValueError(f"{name} = {ch} is not a channel 1..16")
        if steer == throttle:
            raise ValueError(f"RCMAP_ROLL and RCMAP_THROTTLE are both channel {steer}")
        return cls(RcCalibration.from_params(steer, params),
                   RcCalibration.from_params(throttle, params))

    def to_pwm(self, nT: float, nS: float) -> dict[int, int]:
        """Our commands to PWM by channel: nS > 0 (port) is steering below trim."""
        return {self.throttle.channel: self.throttle.to_pwm(nT),
                self.steering.channel: self.steering.to_pwm(-nS)}

    def to_commands(self, pwm_by_channel: dict[int, float]) -> tuple[float, float]:
        """PWM by channel back to (nT, nS) percent as the autopilot reads them."""
        nT = self.throttle.to_percent(pwm_by_channel.get(self.throttle.channel, self.throttle.trim))
        nS = -self.steering.to_percent(pwm_by_channel.get(self.steering.channel, self.steering.trim))
        return nT, nS
