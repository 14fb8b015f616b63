"""The autopilot's EKF messages -> our state [x, y, psi, u, v, r], and a short prediction.

Positions come from GLOBAL_POSITION_INT converted to local NED around the geodetic origin
that places the scenario on the Earth (flat earth, as ArduPilot's own `Location` offsets:
fine over a canal's few kilometres), or from LOCAL_POSITION_NED, which is measured from the
EKF origin (wherever the first GPS fix came), moved by where that origin lies. Heading and yaw rate come from ATTITUDE; body velocities u, v are the NED
velocity rotated by the heading. A state is stamped with the autopilot's `time_boot_ms` and
with the bridge's clock when it arrived (the older of its two messages).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from controller.geodetic import geodetic_to_ned
from controller.geometry import wrap_angle

# EKF_STATUS_REPORT.flags (MAVLink EKF_STATUS_FLAGS).
EKF_ATTITUDE = 1
EKF_VELOCITY_HORIZ = 2
EKF_POS_HORIZ_REL = 8
EKF_POS_HORIZ_ABS = 16
EKF_CONST_POS_MODE = 128
EKF_UNINITIALIZED = 1024

MAX_ATTITUDE_SKEW_S = 0.5  # attitude older than this next to a position is not extrapolated


@dataclass(frozen=True)
class EkfState:
    """One state estimate: [x, y, psi, u, v, r] (NED, rad, body m/s, rad/s) and its times."""

    time_boot_s: float  # autopilot time of the position (time_boot_ms / 1000)
    received_s: float  # bridge clock when the older of its messages arrived
    x: float
    y: float
    psi: float
    u: float
    v: float
    r: float

    @property
    def vector(self) -> np.ndarray:
        return np.array([self.x, self.y, self.psi, self.u, self.v, self.r], float)

    @property
    def speed_mps(self) -> float:
        return math.hypot(self.u, self.v)


def horizontal_position_ok(flags: int) -> bool:
    """EKF_STATUS_REPORT flags -> a usable horizontal position, as ArduPilot Rover judges it
    when armed (`Rover::ekf_position_ok`: absolute or relative position, not constant-position
    mode), plus attitude and horizontal velocity, which the controller also needs."""
    flags = int(flags)
    need = EKF_ATTITUDE | EKF_VELOCITY_HORIZ
    return ((flags & need) == need
            and bool(flags & (EKF_POS_HORIZ_ABS | EKF_POS_HORIZ_REL))
            and not flags & (EKF_CONST_POS_MODE | EKF_UNINITIALIZED))


def body_velocity(v_north: float, v_east: float, psi: float) -> tuple[float, float]:
    """NED horizontal velocity -> body (u forward, v starboard) for heading psi."""
    c, s = math.cos(psi), math.sin(psi)
    return c * v_north + s * v_east, -s * v_north + c * v_east


def _heading_at(attitude, time_boot_s: float) -> float:
    """ATTITUDE's yaw carried to the position's time with its yaw rate (if close in time)."""
    dt = time_boot_s - attitude.time_boot_ms * 1e-3
    psi = float(attitude.yaw)
    if abs(dt) <= MAX_ATTITUDE_SKEW_S:
        psi += float(attitude.yawspeed) * dt
    return float(wrap_angle(psi))


def state_from_local(attitude, local, received_s: float, offset_ne=(0.0, 0.0)) -> EkfState:
    """ATTITUDE + LOCAL_POSITION_NED (m, m/s, from the EKF origin) -> EkfState, the position
    moved by `offset_ne` (where the EKF origin lies in the frame wanted)."""
    t = local.time_boot_ms * 1e-3
    psi = _heading_at(attitude, t)
    u, v = body_velocity(local.vx, local.vy, psi)
    return EkfState(t, float(received_s), float(local.x) + float(offset_ne[0]),
                    float(local.y) + float(offset_ne[1]), psi, u, v, float(attitude.yawspeed))


def state_from_global(attitude, position, origin, received_s: float) -> EkfState:
    """ATTITUDE + GLOBAL_POSITION_INT (degE7, cm/s) -> EkfState in local NED around `origin`."""
    t = position.time_boot_ms * 1e-3
    psi = _heading_at(attitude, t)
    north, east = geodetic_to_ned(position.lat * 1e-7, position.lon * 1e-7, origin)
    u, v = body_velocity(position.vx * 0.01, position.vy * 0.01, psi)
    return EkfState(t, float(received_s), north, east, psi, u, v, float(attitude.yawspeed))


def predict_vector(state, dt: float) -> np.ndarray:
    """[x, y, psi, u, v, r] moved `dt` seconds ahead with constant body velocities and yaw rate
    (a steady turn: exact for that kinematics, no dynamics, no current). Over the link delay
    (tens of milliseconds) the boat's accelerations change little, so this is enough."""
    x, y, psi, u, v, r = (float(s) for s in np.asarray(state, float).reshape(6))
    dt = float(dt)
    psi1 = psi + r * dt
    if abs(r * dt) < 1e-6:  # straight line (midpoint heading)
        pm = psi + 0.5 * r * dt
        dx = (u * math.cos(pm) - v * math.sin(pm)) * dt
        dy = (u * math.sin(pm) + v * math.cos(pm)) * dt
    else:
        ds, dc = math.sin(psi1) - math.sin(psi), math.cos(psi1) - math.cos(psi)
        dx = (u * ds + v * dc) / r
        dy = (-u * dc + v * ds) / r
    psi1 = float(wrap_angle(psi1))
    return np.array([x + dx, y + dy, psi1, u, v, r])


def predict(state: EkfState, dt: float) -> EkfState:
    """`state` moved `dt` seconds ahead (see `predict_vector`); its autopilot time moves too."""
    x, y, psi, u, v, r = predict_vector(state.vector, dt)
    return replace(state, time_boot_s=state.time_boot_s + float(dt), x=x, y=y, psi=psi)
