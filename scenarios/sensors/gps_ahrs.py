"""Simulated navigation sensors: RTK GPS (5 Hz) and AHRS (100 Hz), as on the paper's boat.

Each sensor turns the true state (and, for the AHRS, the body accelerations the plant
reports) into a noisy measurement with its own seeded generator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.geometry import wrap_angle


@dataclass(frozen=True)
class GpsConfig:
    rate_hz: float = 5.0
    pos_sigma_m: float = 0.02  # RTK: +-0.01 m + 1 ppm CEP
    vel_sigma_mps: float = 0.02


@dataclass(frozen=True)
class AhrsConfig:
    rate_hz: float = 100.0
    heading_sigma_rad: float = float(np.radians(0.1))
    yaw_rate_sigma_radps: float = float(np.radians(0.2))
    accel_sigma_mps2: float = 0.02


@dataclass(frozen=True)
class GpsFix:
    position_ne: np.ndarray  # m, NED
    velocity_ne: np.ndarray  # m/s, NED


@dataclass(frozen=True)
class AhrsSample:
    heading_rad: float
    yaw_rate_radps: float
    accel_body: np.ndarray  # specific force (a_x, a_y) in m/s^2, body frame


def body_specific_force(state, xdot) -> np.ndarray:
    """(a_x, a_y) an accelerometer feels: nu_dot + omega x v in the horizontal plane."""
    u, v, r = state[3], state[4], state[5]
    return np.array([xdot[3] - r * v, xdot[4] + r * u])


class GpsSensor:
    def __init__(self, config: GpsConfig = GpsConfig(), seed: int = 0):
        self.config = config
        self._rng = np.random.default_rng(seed)

    def measure(self, state) -> GpsFix:
        x, y, psi, u, v = state[:5]
        c, s = np.cos(psi), np.sin(psi)
        vel = np.array([c * u - s * v, s * u + c * v])
        cfg = self.config
        return GpsFix(
            position_ne=np.array([x, y]) + self._rng.normal(0.0, cfg.pos_sigma_m, 2),
            velocity_ne=vel + self._rng.normal(0.0, cfg.vel_sigma_mps, 2),
        )


class AhrsSensor:
    def __init__(self, config: AhrsConfig = AhrsConfig(), seed: int = 0):
        self.config = config
        self._rng = np.random.default_rng(seed)

    def measure(self, state, xdot) -> AhrsSample:
        cfg, rng = self.config, self._rng
        return AhrsSample(
            heading_rad=float(wrap_angle(state[2] + rng.normal(0.0, cfg.heading_sigma_rad))),
            yaw_rate_radps=float(state[5] + rng.normal(0.0, cfg.yaw_rate_sigma_radps)),
            accel_body=body_specific_force(state, xdot) + rng.normal(0.0, cfg.accel_sigma_mps2, 2),
        )
