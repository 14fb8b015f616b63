"""Navigation filter: an EKF (filterpy) over GPS and AHRS, as on the paper's boat (§IV-C).

State `[x, y, psi, u, v, r]` (NED position, heading, body velocity over ground, yaw rate).
The prediction is kinematic and driven by the AHRS's body-frame specific force, so the
filter does not depend on the identified model it is used to control:

    x' = u cos psi - v sin psi      u' = a_x + r v
    y' = u sin psi + v cos psi      v' = a_y - r u
    psi' = r                        r' = 0 (random walk)

Updates: AHRS heading and yaw rate (100 Hz), GPS position and NED velocity (5 Hz).

The filter runs 100 prediction and update pairs per simulated second, so it runs as a C
kernel (`controller/kernels/nav_filter.c`, about 20 times cheaper than filterpy's calls);
filterpy's EKF with the same model stays as its reference (the tests hold the two within
1e-12) and as the fallback where nothing can be compiled (`backend="filterpy"`).
"""

from __future__ import annotations

import ctypes
import math

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from .errors import InputError
from .geometry import wrap_angle
from .kernels import Kernel, pointer

_KERNEL = Kernel(Path(__file__).with_name("kernels") / "nav_filter.c", {
    "nav_predict": (None, [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_double, ctypes.c_int,
                           ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double]),
    "nav_update": (None, [ctypes.c_void_p] * 2 + [ctypes.c_int] + [ctypes.c_void_p] * 2)})


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


def _angle_residual(a, b):
    y = np.subtract(a, b)
    y[0] = wrap_angle(y[0])
    return y


def _h_position(x):
    return x[:2]


def _H_position(x):
    H = np.zeros((2, 6))
    H[0, 0] = H[1, 1] = 1.0
    return H


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


def _h_attitude(x):
    return x[[2, 5]]


def _H_attitude(x):
    H = np.zeros((2, 6))
    H[0, 2] = H[1, 5] = 1.0
    return H


class _StrapdownEKF(ExtendedKalmanFilter):
    """filterpy's EKF with the nonlinear kinematic prediction above (input: a_x, a_y)."""

    def predict_x(self, u=None):
        ax, ay = (0.0, 0.0) if u is None else u
        x, y, psi, su, sv, r = self.x
        dt = self._dt
        c, s = np.cos(psi), np.sin(psi)
        self.x = np.array([
            x + dt * (c * su - s * sv),
            y + dt * (s * su + c * sv),
            wrap_angle(psi + dt * r),
            su + dt * (ax + r * sv),
            sv + dt * (ay - r * su),
            r,
        ])


class NavigationFilter:
    """EKF estimating the boat's pose and velocity from GPS and AHRS measurements.

    backend: "c" (the compiled kernel), "filterpy" (its reference), or "auto" (the kernel
    when it can be built, else filterpy with a warning)."""

    def __init__(self, initial_state, config: NavConfig = NavConfig(), backend: str = "auto"):
        x0 = np.asarray(initial_state, float).reshape(-1)
        if x0.shape != (6,) or not np.all(np.isfinite(x0)):
            raise InputError(f"navigation filter: initial state must be 6 finite numbers, got {x0}")
        if backend not in ("auto", "c", "filterpy"):
            raise InputError(f"navigation filter: backend must be auto, c or filterpy, "
                             f"got {backend!r}")
        self.config = config
        cfg = config
        P0 = np.diag([
            cfg.initial_pos_sigma_m**2, cfg.initial_pos_sigma_m**2,
            cfg.initial_heading_sigma_rad**2,
            cfg.initial_vel_sigma_mps**2, cfg.initial_vel_sigma_mps**2,
            cfg.initial_yaw_rate_sigma_radps**2,
        ])
        self._R_pos = np.eye(2) * cfg.gps_pos_sigma_m**2
        self._R_vel = np.eye(2) * cfg.gps_vel_sigma_mps**2
        self._R_att = np.diag([cfg.heading_sigma_rad**2, cfg.yaw_rate_sigma_radps**2])
        self._q_a, self._q_r = cfg.accel_noise_mps2**2, cfg.yaw_accel_noise_radps2**2
        lib = _KERNEL() if backend != "filterpy" else None
        if backend == "c" and lib is None:
            raise RuntimeError("navigation filter: the C kernel could not be built (see the "
                               "warning above)")
        self.backend = "c" if lib is not None else "filterpy"
        if lib is not None:
            self._x, self._P = x0.copy(), P0.copy()
            self._c_predict, self._c_update = lib.nav_predict, lib.nav_update
            self._px, self._pP = pointer(self._x), pointer(self._P)
            self._z = np.zeros(2)
            self._pz = pointer(self._z)
            self._pR = {k: pointer(r) for k, r in
                        ((0, self._R_pos), (1, self._R_vel), (2, self._R_att))}
            self._ekf = None
        else:
            self._ekf = _StrapdownEKF(dim_x=6, dim_z=2)
            self._ekf._dt = 0.0
            self._ekf.x = x0.copy()
            self._ekf.P = P0

    @property
    def state(self) -> np.ndarray:
        return (self._x if self._ekf is None else self._ekf.x).copy()

    @property
    def covariance(self) -> np.ndarray:
        return (self._P if self._ekf is None else self._ekf.P).copy()

    def predict(self, dt: float, accel_body=None) -> None:
        """Propagate by dt seconds with the body specific force (a_x, a_y) if the AHRS has it."""
        if dt <= 0.0:
            return
        if accel_body is not None and not np.all(np.isfinite(accel_body)):
            accel_body = None  # a bad IMU sample: coast instead of corrupting the state
        if self._ekf is None:
            ax, ay = (0.0, 0.0) if accel_body is None else (float(accel_body[0]),
                                                            float(accel_body[1]))
            self._c_predict(self._px, self._pP, dt, accel_body is not None, ax, ay,
                            self._q_a, self._q_r)
            return
        ekf = self._ekf
        x, y, psi, u, v, r = ekf.x
        c, s = np.cos(psi), np.sin(psi)
        F = np.eye(6)
        F[0, 2:5] = dt * np.array([-s * u - c * v, c, -s])
        F[1, 2:5] = dt * np.array([c * u - s * v, s, c])
        F[2, 5] = dt
        F[3, 4], F[3, 5] = dt * r, dt * v
        F[4, 3], F[4, 5] = -dt * r, -dt * u
        q_a, q_r = self._q_a, self._q_r
        # Discrete white-acceleration noise on (position, velocity) pairs and on r.
        G = np.zeros((6, 3))
        G[0, 0], G[0, 1] = 0.5 * dt**2 * c, -0.5 * dt**2 * s
        G[1, 0], G[1, 1] = 0.5 * dt**2 * s, 0.5 * dt**2 * c
        G[3, 0] = G[4, 1] = dt
        G[2, 2], G[5, 2] = 0.5 * dt**2, dt
        Q = G @ np.diag([q_a, q_a, q_r]) @ G.T
        ekf.F, ekf.Q, ekf._dt = F, Q, dt
        ekf.predict(u=accel_body)

    def _update_c(self, kind: int, z0: float, z1: float) -> None:
        self._z[0], self._z[1] = z0, z1
        self._c_update(self._px, self._pP, kind, self._pz, self._pR[kind])

    def update_gps(self, position_ne=None, velocity_ne=None) -> None:
        """Fuse a GPS fix: NED position (m) and/or NED velocity (m/s). Non-finite parts are skipped."""
        ekf = self._ekf
        if position_ne is not None and np.all(np.isfinite(position_ne)):
            if ekf is None:
                self._update_c(0, *map(float, position_ne))
            else:
                ekf.update(np.asarray(position_ne, float), _H_position, _h_position,
                           R=self._R_pos)
        if velocity_ne is not None and np.all(np.isfinite(velocity_ne)):
            if ekf is None:
                self._update_c(1, *map(float, velocity_ne))
            else:
                ekf.update(np.asarray(velocity_ne, float), _H_velocity, _h_velocity,
                           R=self._R_vel)

    def update_ahrs(self, heading_rad: float, yaw_rate_radps: float) -> None:
        """Fuse an AHRS sample: heading (rad, wrapped) and yaw rate (rad/s)."""
        if not (math.isfinite(heading_rad) and math.isfinite(yaw_rate_radps)):
            return
        ekf = self._ekf
        if ekf is None:
            self._update_c(2, float(heading_rad), float(yaw_rate_radps))
            return
        z = np.array([heading_rad, yaw_rate_radps], float)
        z[0] = ekf.x[2] + wrap_angle(z[0] - ekf.x[2])
        ekf.update(z, _H_attitude, _h_attitude, R=self._R_att, residual=_angle_residual)
        ekf.x[2] = wrap_angle(ekf.x[2])
