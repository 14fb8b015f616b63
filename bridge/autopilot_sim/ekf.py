"""The simulated autopilot's navigation estimate: truth plus bounded, seeded, coloured noise.

Not a filter: each error is a first-order Gauss-Markov process (a random walk pulled back to
zero with time constant `tau`, stationary standard deviation `sigma`, clipped at 3 sigma),
which is what an EKF's error looks like to its user: slowly wandering position, small
heading error, velocity noise. The estimate is not ready (attitude only) until `delay_s`
after boot, like an EKF waiting for GPS. The same seed and the same steps give the same
numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.geometry import wrap_angle



@dataclass(frozen=True)
class NoiseSpec:
    """Standard deviation and time constant of each error (SI units)."""

    pos_sigma_m: float = 0.2
    pos_tau_s: float = 20.0
    heading_sigma_rad: float = math.radians(0.3)
    heading_tau_s: float = 10.0
    vel_sigma_mps: float = 0.05
    vel_tau_s: float = 1.0
    rate_sigma_radps: float = math.radians(0.2)
    rate_tau_s: float = 0.2
    # A heading bias, as a real EKF's from a badly calibrated compass or a magnetic
    # disturbance: constant, plus a slow wander (Gauss-Markov, drawn from its own stream so
    # that the other errors of a seed stay the same). The velocity over ground stays the
    # GPS's (NED); the body-frame velocity the bridge derives with the biased heading then
    # shows a sideslip the boat does not have, as ArduPilot's does.
    heading_bias_rad: float = 0.0
    heading_wander_sigma_rad: float = 0.0
    heading_wander_tau_s: float = 300.0
    # GPS glitches the EKF takes in: (at_s, duration_s, north_m, east_m), times from the
    # EKF's start; the position is off by (north, east) for the glitch's duration, jumping
    # there and back, as ArduPilot's EKF does when it resets to a GPS that jumped beyond its
    # innovation gate. The velocity stays right (it comes from the GPS's Doppler).
    gps_glitches: tuple = ()

    def __post_init__(self) -> None:
        for name in ("pos_sigma_m", "pos_tau_s", "heading_sigma_rad", "heading_tau_s",
                     "vel_sigma_mps", "vel_tau_s", "rate_sigma_radps", "rate_tau_s",
                     "heading_bias_rad", "heading_wander_sigma_rad", "heading_wander_tau_s"):
            value = getattr(self, name)
            if not math.isfinite(value) or (value < 0 and name != "heading_bias_rad") \
                    or (name.endswith("tau_s") and value <= 0):
                raise ValueError(f"EKF noise {name} must be a finite number"
                                 f"{'' if name == 'heading_bias_rad' else ' >= 0'}"
                                 f"{' > 0' if name.endswith('tau_s') else ''}, got {value!r}")
        for glitch in self.gps_glitches:
            try:
                at, duration, north, east = (float(v) for v in glitch)
            except (TypeError, ValueError):
                raise ValueError(f"GPS glitch {glitch!r}: expected (at_s, duration_s, north_m, "
                                 "east_m)") from None
            if not (all(math.isfinite(v) for v in (at, duration, north, east)) and at >= 0
                    and duration > 0):
                raise ValueError(f"GPS glitch {glitch!r}: at_s >= 0, duration_s > 0 and finite "
                                 "offsets needed")


@dataclass(frozen=True)
class Estimate:
    """What the autopilot believes: NED position and velocity over ground, heading, yaw rate."""

    north_m: float
    east_m: float
    vn_mps: float
    ve_mps: float
    psi_rad: float  # wrapped to [-pi, pi)
    r_radps: float


class EkfModel:
    """Errors for [north, east, psi, vn, ve, r], advanced with the physics."""

    def __init__(self, seed: int, delay_s: float, spec: NoiseSpec = NoiseSpec()):
        self.delay_s = float(delay_s)
        self.spec = spec
        self._rng = np.random.default_rng(seed)
        s = spec
        self._sigma = np.array([s.pos_sigma_m, s.pos_sigma_m, s.heading_sigma_rad,
                                s.vel_sigma_mps, s.vel_sigma_mps, s.rate_sigma_radps])
        self._tau = np.array([s.pos_tau_s, s.pos_tau_s, s.heading_tau_s,
                              s.vel_tau_s, s.vel_tau_s, s.rate_tau_s])
        self._err = np.clip(self._rng.standard_normal(6), -3, 3) * self._sigma
        self._dt = None
        self._a = self._b = None
        self._t = 0.0  # seconds since the EKF started (the glitches' clock)
        self._wander = 0.0
        self._wander_rng = None
        if spec.heading_wander_sigma_rad > 0:
            self._wander_rng = np.random.default_rng([seed, 1])
            self._wander = float(np.clip(self._wander_rng.standard_normal(), -3, 3)
                                 * spec.heading_wander_sigma_rad)

    def step(self, dt: float) -> None:
        """Advance every error by `dt` seconds (exact discretisation of the Gauss-Markov law)."""
        self._t += dt
        if dt != self._dt:
            self._dt = dt
            self._a = np.exp(-dt / self._tau)
            self._b = self._sigma * np.sqrt(1.0 - self._a ** 2)
        e = self._a * self._err + self._b * self._rng.standard_normal(6)
        self._err = np.clip(e, -3 * self._sigma, 3 * self._sigma)
        if self._wander_rng is not None:
            s = self.spec
            a = math.exp(-dt / s.heading_wander_tau_s)
            w = a * self._wander + s.heading_wander_sigma_rad * math.sqrt(1.0 - a * a) \
                * self._wander_rng.standard_normal()
            self._wander = min(max(w, -3 * s.heading_wander_sigma_rad),
                               3 * s.heading_wander_sigma_rad)

    @property
    def heading_bias_rad(self) -> float:
        """The heading error's bias part now: the constant bias and the wander."""
        return self.spec.heading_bias_rad + self._wander

    @property
    def glitch_ne(self) -> tuple[float, float]:
        """The position offset of the GPS glitch under way (0, 0: none)."""
        north = east = 0.0
        for at, duration, dn, de in self.spec.gps_glitches:
            if at <= self._t < at + duration:
                north, east = north + float(dn), east + float(de)
        return north, east

    def ready(self, since_boot_s: float) -> bool:
        return since_boot_s >= self.delay_s

    def estimate(self, state) -> Estimate:
        """Truth [x, y, psi, u, v, r] plus the current errors; velocity rotated to NED."""
        x, y, psi, u, v, r = (float(s) for s in state)
        c, s = math.cos(psi), math.sin(psi)
        e = self._err
        gn, ge = self.glitch_ne if self.spec.gps_glitches else (0.0, 0.0)
        return Estimate(
            north_m=x + e[0] + gn, east_m=y + e[1] + ge,
            vn_mps=c * u - s * v + e[3], ve_mps=s * u + c * v + e[4],
            psi_rad=float(wrap_angle(psi + e[2] + self.heading_bias_rad)), r_radps=r + e[5],
        )
