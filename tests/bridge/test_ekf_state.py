"""EKF messages -> [x, y, psi, u, v, r], flat-earth geodetic conversion, delay prediction."""

from __future__ import annotations

import math
from types import SimpleNamespace as Msg

import numpy as np
import pytest

from controller.geodetic import geodetic_to_ned, ned_to_geodetic
from bridge.onboard.ekf_state import (EkfState, body_velocity, horizontal_position_ok,
                              predict, predict_vector, state_from_global,
                              state_from_local)


def attitude(t_ms, yaw, yawspeed=0.0):
    return Msg(time_boot_ms=t_ms, yaw=yaw, yawspeed=yawspeed)


def test_body_velocity_rotates_ned_by_heading():
    # heading east: moving east is surge, moving north is to port (negative sway)
    u, v = body_velocity(0.0, 2.0, math.pi / 2)
    assert (u, v) == pytest.approx((2.0, 0.0), abs=1e-12)
    u, v = body_velocity(1.0, 0.0, math.pi / 2)
    assert (u, v) == pytest.approx((0.0, -1.0), abs=1e-12)


def test_state_from_local_position():
    att = attitude(1000, math.radians(30), 0.05)
    local = Msg(time_boot_ms=1000, x=12.0, y=-4.0, vx=math.cos(math.radians(30)) * 2,
                vy=math.sin(math.radians(30)) * 2)
    s = state_from_local(att, local, received_s=5.0)
    assert s.vector == pytest.approx([12, -4, math.radians(30), 2, 0, 0.05], abs=1e-9)
    assert s.time_boot_s == 1.0 and s.received_s == 5.0 and s.speed_mps == pytest.approx(2.0)


def test_heading_is_carried_to_the_position_time_with_the_yaw_rate():
    s = state_from_local(attitude(900, 0.2, 0.1), Msg(time_boot_ms=1000, x=0, y=0, vx=0, vy=0), 0.0)
    assert s.psi == pytest.approx(0.21)
    far = state_from_local(attitude(0, 0.2, 0.1), Msg(time_boot_ms=1000, x=0, y=0, vx=0, vy=0), 0.0)
    assert far.psi == pytest.approx(0.2)  # too far apart: not extrapolated


def test_geodetic_round_trip_and_scale():
    origin = (36.0345, 129.3720, 0.0)
    n, e = geodetic_to_ned(*ned_to_geodetic(250.0, -120.0, origin), origin)
    assert (n, e) == pytest.approx((250.0, -120.0), abs=1e-6)
    # one arc-minute of latitude is about a nautical mile
    n, _ = geodetic_to_ned(origin[0] + 1 / 60, origin[1], origin)
    assert n == pytest.approx(1852, rel=2e-3)
    # across the antimeridian
    n, e = geodetic_to_ned(0.0, -179.9999, (0.0, 179.9999, 0.0))
    assert e == pytest.approx(22.26, abs=0.05)


def test_state_from_global_position():
    origin = (52.0, 4.0, 0.0)
    lat, lon = ned_to_geodetic(100.0, 50.0, origin)
    gpi = Msg(time_boot_ms=2000, lat=int(round(lat * 1e7)), lon=int(round(lon * 1e7)), vx=150, vy=0)
    s = state_from_global(attitude(2000, 0.0), gpi, origin, received_s=1.0)
    assert (s.x, s.y) == pytest.approx((100.0, 50.0), abs=0.02)  # 1e-7 deg ~ 1 cm
    assert (s.u, s.v) == pytest.approx((1.5, 0.0))


@pytest.mark.parametrize("flags,ok", [
    (1 | 2 | 16, True),  # absolute position
    (1 | 2 | 8, True),  # relative position
    (1 | 2 | 512, False),  # predicted only (fine disarmed, not to drive)
    (1 | 2 | 16 | 128, False),  # constant position mode
    (1 | 2 | 16 | 1024, False),  # uninitialised
    (2 | 16, False),  # no attitude
    (1 | 16, False),  # no horizontal velocity
    (0, False),
])
def test_horizontal_position_ok(flags, ok):
    assert horizontal_position_ok(flags) is ok


def test_prediction_straight_and_turning():
    x = predict_vector([0, 0, 0, 2.0, 0.5, 0.0], 0.5)
    assert x == pytest.approx([1.0, 0.25, 0, 2.0, 0.5, 0.0])
    # a steady turn: a quarter circle of radius u / r
    r = 0.1
    x = predict_vector([0, 0, 0, 1.0, 0.0, r], (math.pi / 2) / r)
    assert x[:3] == pytest.approx([10.0, 10.0, math.pi / 2], abs=1e-9)
    # matches small-step integration
    s = np.array([3.0, -2.0, 1.0, 1.8, -0.2, -0.05])
    y = s.copy()
    for _ in range(1000):
        y = predict_vector(y, 0.0004)
    assert predict_vector(s, 0.4) == pytest.approx(y, abs=1e-9)


def test_predict_keeps_the_dataclass_and_moves_its_time():
    s = EkfState(10.0, 3.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0)
    p = predict(s, 0.25)
    assert isinstance(p, EkfState) and p.x == pytest.approx(0.5)
    assert p.time_boot_s == pytest.approx(10.25) and p.received_s == 3.0
