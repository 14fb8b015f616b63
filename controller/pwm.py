"""Throttle and steering in percent <-> PWM, as ArduPilot Rover reads its RC inputs and
writes its servo outputs. One implementation for the bridge (RC overrides out, the simulated
autopilot reading them and driving its servos) and for identification (servo outputs in a
DataFlash log back to commands).

RC inputs (`RCn_MIN/MAX/TRIM/DZ/REVERSED`, `RC_Channel::pwm_to_angle_dz_trim`): trim reads
zero, so does the dead zone around it, and each side scales linearly to its end. Rover reads
its throttle in whole percent and its steering in centidegrees of a 45 degree range (4500
units a side), with C integer division: a reading is truncated toward zero. Servo outputs
(`SERVOn_MIN/MAX/TRIM/REVERSED`, `SRV_Channel::pwm_from_angle`): the same two linear sides,
no dead zone; `SERVOn_FUNCTION` says which output steers (26) and which throttles (70).

Sense: above trim is positive (throttle ahead, steering to starboard) unless reversed. In our
model `nS > 0` turns to port, so `nS > 0` is steering below trim.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

THROTTLE_UNITS = 100  # Rover's throttle input: whole percent (RC_Channel::set_angle(100))
STEERING_UNITS = 4500  # Rover's steering input: centidegrees of 45 deg (SERVO_MAX)
SERVO_FUNCTION_STEERING = 26  # SERVOn_FUNCTION: GroundSteering
SERVO_FUNCTION_THROTTLE = 70  # SERVOn_FUNCTION: Throttle
N_SERVOS = 32


@dataclass(frozen=True)
class PwmChannel:
    """One channel's calibration in microseconds (ArduPilot stores them as integers).

    `units` is the resolution of the autopilot's reading of an input (per side of trim);
    None reads continuously (servo outputs, what a servo or an ESC does with its PWM).
    """

    channel: int
    min: int = 1100
    max: int = 1900
    trim: int = 1500
    dz: int = 0
    reversed: bool = False
    units: int | None = None
    label: str = field(default="", compare=False)  # "RC3", "SERVO1": names it in errors

    @property
    def name(self) -> str:
        return self.label or f"channel {self.channel}"

    def __post_init__(self):
        for name in ("min", "max", "trim", "dz"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"{self.name}_{name.upper()} = {value!r} is not a number")
            object.__setattr__(self, name, int(round(value)))
        object.__setattr__(self, "reversed", bool(self.reversed))
        if not self.min < self.trim < self.max:
            raise ValueError(f"{self.name}: need MIN < TRIM < MAX, got "
                             f"{self.min} / {self.trim} / {self.max}")
        if not 0 <= self.dz < min(self.trim - self.min, self.max - self.trim):
            raise ValueError(f"{self.name}: dead zone {self.dz} us leaves no travel")

    def _spans(self) -> tuple[int, int]:
        """Travel beyond the dead zone above and below trim (us)."""
        return self.max - self.trim - self.dz, self.trim - self.dz - self.min

    def to_percent(self, pwm: float) -> float:
        """PWM to percent of travel in [-100, 100] as the autopilot reads it (dead zone 0,
        truncated to its resolution)."""
        pwm = max(self.min, min(self.max, float(pwm)))
        up, down = self._spans()
        if pwm > self.trim + self.dz:
            off, span, sign = pwm - self.trim - self.dz, up, 1.0
        elif pwm < self.trim - self.dz:
            off, span, sign = self.trim - self.dz - pwm, down, -1.0
        else:
            return 0.0
        if self.reversed:
            sign = -sign
        if self.units is None:
            return 100.0 * sign * off / span
        counts = (self.units * int(round(off))) // span  # integer division, as the firmware's
        return sign * 100.0 * counts / self.units

    def to_pwm(self, percent: float) -> int:
        """The PWM whose reading (`to_percent`) is the percent meant, to the reading's
        resolution: the nearest whole unit, reached by the smallest offset from trim that reads
        at least that. A non-zero command therefore lands beyond the dead zone (the smallest
        correction moves), full travel at MIN or MAX; only a command under half a unit (0.5 %
        throttle, 0.011 % steering) is sent as trim."""
        if not math.isfinite(percent):
            raise ValueError(f"{self.name}: command {percent!r} is not a number")
        p = max(-100.0, min(100.0, float(percent)))
        if self.reversed:
            p = -p
        up, down = self._spans()
        span = up if p > 0 else down
        if self.units is None:
            d = int(round(abs(p) * span / 100.0))
            if self.dz and p != 0.0:
                d = max(d, 1)
        else:
            k = int(abs(p) * self.units / 100.0 + 0.5 + 1e-9)  # the reading meant, whole units
            d = -(-k * span // self.units) if k else 0  # ceil: reads at least k
        d = min(d, span)
        if d == 0:
            return self.trim
        return self.trim + self.dz + d if p > 0 else self.trim - self.dz - d


def rc_input(channel: int, params, units: int | None = None) -> PwmChannel:
    """RCn_* of a parameter table (name -> value), ArduPilot's defaults where missing."""
    p = lambda k, d: params.get(f"RC{channel}_{k}", d)  # noqa: E731
    return PwmChannel(channel, p("MIN", 1100), p("MAX", 1900), p("TRIM", 1500), p("DZ", 0),
                      bool(p("REVERSED", 0)), units, f"RC{channel}")


def servo_output(channel: int, params) -> PwmChannel:
    """SERVOn_* of a parameter table, ArduPilot's defaults where missing (no dead zone)."""
    p = lambda k, d: params.get(f"SERVO{channel}_{k}", d)  # noqa: E731
    return PwmChannel(channel, p("MIN", 1100), p("MAX", 1900), p("TRIM", 1500), 0,
                      bool(p("REVERSED", 0)), None, f"SERVO{channel}")


def servo_channel(params, function: int) -> int | None:
    """The first servo output n with SERVOn_FUNCTION = `function` (None: none has it)."""
    for n in range(1, N_SERVOS + 1):
        value = params.get(f"SERVO{n}_FUNCTION")
        if value is not None and int(value) == function:
            return n
    return None


@dataclass(frozen=True)
class CommandChannels:
    """The steering and throttle channels: our (nT, nS) percent <-> PWM by channel."""

    steering: PwmChannel
    throttle: PwmChannel

    def __post_init__(self):
        if self.steering.channel == self.throttle.channel:
            raise ValueError(f"steering and throttle are both channel {self.steering.channel}")

    @classmethod
    def from_rc_params(cls, params) -> "CommandChannels":
        """RC inputs: RCMAP_ROLL (steering), RCMAP_THROTTLE and their RCn_* calibration."""
        steer = int(params.get("RCMAP_ROLL", 1))
        throttle = int(params.get("RCMAP_THROTTLE", 3))
        for name, ch in (("RCMAP_ROLL", steer), ("RCMAP_THROTTLE", throttle)):
            if not 1 <= ch <= 16:
                raise ValueError(f"{name} = {ch} is not a channel 1..16")
        if steer == throttle:
            raise ValueError(f"RCMAP_ROLL and RCMAP_THROTTLE are both channel {steer}")
        return cls(rc_input(steer, params, STEERING_UNITS),
                   rc_input(throttle, params, THROTTLE_UNITS))

    @classmethod
    def from_servo_params(cls, params) -> "CommandChannels":
        """Servo outputs: SERVOn_FUNCTION 26 (steering) and 70 (throttle), SERVOn_*."""
        found = {}
        for what, function in (("steering", SERVO_FUNCTION_STEERING),
                               ("throttle", SERVO_FUNCTION_THROTTLE)):
            n = servo_channel(params, function)
            if n is None:
                raise ValueError(f"no servo output has SERVOn_FUNCTION = {function} ({what}); "
                                 "skid steering (73/74) is not supported")
            found[what] = servo_output(n, params)
        return cls(found["steering"], found["throttle"])

    def to_pwm(self, nT: float, nS: float) -> dict[int, int]:
        """Our commands to PWM by channel: nS > 0 (port) is steering below trim."""
        return {self.throttle.channel: self.throttle.to_pwm(nT),
                self.steering.channel: self.steering.to_pwm(-nS)}

    def to_commands(self, pwm_by_channel) -> tuple[float, float]:
        """PWM by channel back to (nT, nS) percent; a missing channel reads trim."""
        t, s = self.throttle, self.steering
        nT = t.to_percent(pwm_by_channel.get(t.channel, t.trim))
        nS = -s.to_percent(pwm_by_channel.get(s.channel, s.trim))
        return nT + 0.0, nS + 0.0  # no negative zero
