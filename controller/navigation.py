"""Navigation filter: an EKF over GPS and AHRS, as on the paper's boat (§IV-C).

State `[x, y, psi, u, v, r]` (NED position, heading, body velocity over ground, yaw rate).
The prediction is kinematic and driven by the AHRS's body-frame specific force, so the
filter does not depend on the identified model it is used to control:

    x' = u cos psi - v sin psi      u' = a_x + r v
    y' = u sin psi + v cos psi      v' = a_y - r u
    psi' = r                        r' = 0 (random walk)

Updates: AHRS heading and yaw rate (100 Hz), GPS position and NED velocity (5 Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as linalg

from .errors import InputError
from .geometry import wrap_angle


@dataclass(frozen=True)
class NavConfig:
    """Noise figures (1 sigma) of the filter; defaults match the paper's sensors roughly."""

    accel_noise_mps2: float = 0.05  # process: unmodelled acceleration on u, v
    yaw_accel_noise_radps2: float = 0.02  # process: random walk of r
    gps_pos_sigma_m: float = 0.02  # RTK GPS
    gps_vel_sigma_mps: float = 0.02
    heading_sigma_rad: float = np.radians(0.1)
    yaw_rate_sigma_radps: float = np.radians(0.2)
    initial_pos_sigma_m: float = 1.0
    initial_heading_sigma_rad: float = np.radians(5.0)
    initial_vel_sigma_mps: float = 0.5
    initial_yaw_rate_sigma_radps: float = 0.05


def _h_velocity(x):
    c, s = np.cos(x[2]), np.sin(x[2])
    return np.array([c * x[3] - s * x[4], s * x[3] + c * x[4]])


def _H_velocity(x):
    c, s = np.cos(x[2]), np.sin(x[2])
    u, v = x[3], x[4]
    H = np.zeros((2, 6))
    H[0, 2:5] = [-s * u - c * v, c, -s]
    H[1, 2:5] = [c * u - s * v, s, c]
    return H


def _selection(*columns) -> np.ndarray:
    H = np.zeros((len(columns), 6))
    H[range(len(columns)), columns] = 1.0
    return H


def _wrap(angle: float) -> float:
    """`wrap_angle` of one Python float (float arithmetic is numpy's, bit for bit)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


try:  # what scipy.linalg.inv runs once it has checked its argument
    from scipy.linalg._batched_linalg import _inv as _lapack_inv
except ImportError:  # pragma: no cover - another scipy layout
    _lapack_inv = None


def _inv(S: np.ndarray) -> np.ndarray:
    """scipy.linalg.inv(S) (the same LAPACK call) without its per-call argument handling."""
    if _lapack_inv is None or not math.isfinite(S.sum()):
        return linalg.inv(S)  # (raises on non-finite input as before)
    inv, errors = _lapack_inv(S, -1, False, False)
    return linalg.inv(S) if errors else inv


_H_POSITION = _selection(0, 1)
_H_ATTITUDE = _selection(2, 5)


class NavigationFilter:
    """EKF estimating the boat's pose and velocity from GPS and AHRS measurements.

    The equations and their order of evaluation are filterpy's `ExtendedKalmanFilter`
    (predict: P = F P F' + Q; update: Joseph form with K = P H' inv(H P H' + R)), written
    out for this 6-state filter without filterpy's per-call bookkeeping (copies of the prior
    and posterior, argument checks): the same numbers, a fraction of the time at 100 Hz.
    """

    def __init__(self, initial_state, config: NavConfig = NavConfig()):
        x0 = np.asarray(initial_state, float).reshape(-1)
        if x0.shape != (6,) or not np.all(np.isfinite(x0)):
            raise InputError(f"navigation filter: initial state must be 6 finite numbers, got {x0}")
        self.config = config
        self._x = x0.copy()
        cfg = config
        self._P = np.diag([
            cfg.initial_pos_sigma_m**2, cfg.initial_pos_sigma_m**2,
            cfg.initial_heading_sigma_rad**2,
            cfg.initial_vel_sigma_mps**2, cfg.initial_vel_sigma_mps**2,
            cfg.initial_yaw_rate_sigma_radps**2,
        ])
        self._I = np.eye(6)
        self._R_pos = np.eye(2) * cfg.gps_pos_sigma_m**2
        self._R_vel = np.eye(2) * cfg.gps_vel_sigma_mps**2
        self._R_att = np.diag([cfg.heading_sigma_rad**2, cfg.yaw_rate_sigma_radps**2])
        q_a, q_r = cfg.accel_noise_mps2**2, cfg.yaw_accel_noise_radps2**2
        self._Qc = np.diag([q_a, q_a, q_r])

    @property
    def state(self) -> np.ndarray:
        return self._x.copy()

    @property
    def covariance(self) -> np.ndarray:
        return self._P.copy()

    def predict(self, dt: float, accel_body=None) -> None:
        """Propagate by dt seconds with the body specific force (a_x, a_y) if the AHRS has it."""
        if dt <= 0.0:
            return
        # (Python floats: the same IEEE operations as on numpy scalars, without their cost.)
        x, y, psi, u, v, r = self._x.tolist()
        c, s = float(np.cos(psi)), float(np.sin(psi))
        F = np.array([
            [1.0, 0.0, dt * (-s * u - c * v), dt * c, dt * -s, 0.0],
            [0.0, 1.0, dt * (c * u - s * v), dt * s, dt * c, 0.0],
            [0.0, 0.0, 1.0, 0.0, 0.0, dt],
            [0.0, 0.0, 0.0, 1.0, dt * r, dt * v],
            [0.0, 0.0, 0.0, -dt * r, 1.0, -dt * u],
            [0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        ])
        # Discrete white-acceleration noise on (position, velocity) pairs and on r.
        h = 0.5 * dt**2
        G = np.array([
            [h * c, -0.5 * dt**2 * s, 0.0],
            [h * s, h * c, 0.0],
            [0.0, 0.0, h],
            [dt, 0.0, 0.0],
            [0.0, dt, 0.0],
            [0.0, 0.0, dt],
        ])
        Q = G @ self._Qc @ G.T
        if accel_body is None:
            ax, ay = 0.0, 0.0
        else:
            ax, ay = (float(a) for a in accel_body)
            if not (math.isfinite(ax) and math.isfinite(ay)):
                ax, ay = 0.0, 0.0  # a bad IMU sample: coast instead of corrupting the state
        self._x = np.array([
            x + dt * (c * u - s * v),
            y + dt * (s * u + c * v),
            _wrap(psi + dt * r),
            u + dt * (ax + r * v),
            v + dt * (ay - r * u),
            r,
        ])
        self._P = np.dot(F, self._P).dot(F.T) + Q

    def update_gps(self, position_ne=None, velocity_ne=None) -> None:
        """Fuse a GPS fix: NED position (m) and/or NED velocity (m/s). Non-finite parts are skipped."""
        if position_ne is not None and np.all(np.isfinite(position_ne)):
            z = np.asarray(position_ne, float)
            self._update(z - self._x[:2], _H_POSITION, self._R_pos)
        if velocity_ne is not None and np.all(np.isfinite(velocity_ne)):
            z = np.asarray(velocity_ne, float)
            x = self._x
            self._update(z - _h_velocity(x), _H_velocity(x), self._R_vel)

    def update_ahrs(self, heading_rad: float, yaw_rate_radps: float) -> None:
        """Fuse an AHRS sample: heading (rad, wrapped) and yaw rate (rad/s)."""
        z0, z1 = float(heading_rad), float(yaw_rate_radps)
        if not (math.isfinite(z0) and math.isfinite(z1)):
            return
        x = self._x
        psi = float(x[2])
        z0 = psi + _wrap(z0 - psi)
        self._update(np.array([_wrap(z0 - psi), z1 - float(x[5])]), _H_ATTITUDE, self._R_att)
        self._x[2] = _wrap(float(self._x[2]))

    def _update(self, y, H, R) -> None:
        """filterpy's EKF update with the residual y = z - h(x) already formed."""
        P = self._P
        PHT = np.dot(P, H.T)
        S = np.dot(H, PHT) + R
        K = PHT.dot(_inv(S))
        self._x = self._x + np.dot(K, y)
        I_KH = self._I - np.dot(K, H)
        self._P = np.dot(I_KH, P).dot(I_KH.T) + np.dot(K, R).dot(K.T)
