"""LOS law and PID on hand-checked cases; the tracker on the model."""

import numpy as np
import pytest

from controller import model
from controller.baselines.los import (cross_track_error, heading_from_course, lookahead_course,
                                      los_course)
from controller.geometry import Polyline
from controller.baselines.los_pid import LosPidTracker, steady_throttle
from controller.baselines.pid import Pid, PidGains
from controller.params import IDENTIFIED


def test_cross_track_error_sign_and_size():
    # leg heading north from the origin; a point 3 m east is 3 m right of the path
    assert cross_track_error([10, 3], [0, 0], 0.0) == pytest.approx(3.0)
    assert cross_track_error([10, -2], [0, 0], 0.0) == pytest.approx(-2.0)
    # leg heading east: a point to the south is right of the path
    assert cross_track_error([-4, 5], [0, 0], np.pi / 2) == pytest.approx(4.0)


def test_los_course_hand_computed():
    # 3 m right of a northbound path with a 3 m lookahead: steer 45 deg to port (west)
    assert los_course([0, 3], [0, 0], 0.0, 3.0) == pytest.approx(-np.pi / 4)
    # on the path: the path direction
    assert los_course([5 * np.cos(0.3), 5 * np.sin(0.3)], [0, 0], 0.3, 10.0) == pytest.approx(0.3)
    with pytest.raises(ValueError):
        los_course([0, 0], [0, 0], 0.0, 0.0)


def test_lookahead_course_is_fossens_law_on_a_straight_leg():
    path = Polyline([[0, 0], [100 * np.cos(0.3), 100 * np.sin(0.3)]])
    for p in ([10.0, 1.0], [20.0, 12.0], [40.0, 5.0]):
        s = path.project(p)[0]
        assert lookahead_course(p, path, s, 12.0) == pytest.approx(los_course(p, [0, 0], 0.3, 12.0))


def test_lookahead_course_sees_the_curve_ahead():
    # a path of short legs turning east after 10 m: 12 m ahead lies beyond the turn
    path = Polyline([[0, 0], [2, 0], [4, 0], [6, 0], [8, 0], [10, 0], [10, 2], [10, 4], [10, 6]])
    assert lookahead_course([0, 0], path, 0.0, 12.0) > 0.1


def test_heading_compensates_crab_angle():
    # drifting to starboard at v = u: point the bow 45 deg to port of the course
    assert heading_from_course(0.0, 1.0, 1.0) == pytest.approx(-np.pi / 4)


def test_pid_proportional_integral_and_saturation():
    pid = Pid(PidGains(kp=2.0, ki=1.0, out_min=-5, out_max=5))
    assert pid.step(1.0, 0.5) == pytest.approx(2.0 + 0.5)
    assert pid.step(1.0, 0.5) == pytest.approx(2.0 + 1.0)
    for _ in range(100):
        out = pid.step(10.0, 0.5)
    assert out == 5.0
    integral = pid.integral
    pid.step(10.0, 0.5)
    assert pid.integral == integral, "no wind-up while saturated"


def test_pid_rate_limit_and_derivative_on_measurement():
    pid = Pid(PidGains(kp=100.0, out_min=-100, out_max=100, rate_max=10.0))
    assert pid.step(1.0, 0.1) == pytest.approx(1.0)  # 10 %/s over 0.1 s
    pid = Pid(PidGains(kp=0.0, kd=2.0))
    assert pid.step(0.0, 0.1, measurement_rate=3.0) == pytest.approx(-6.0)


def test_pid_derivative_filter_smooths_a_noisy_rate():
    raw = Pid(PidGains(kp=0.0, kd=1.0))
    filtered = Pid(PidGains(kp=0.0, kd=1.0, derivative_filter_s=0.3))
    rng = np.random.default_rng(0)
    rates = 1.0 + rng.normal(0, 0.5, 400)
    a = np.array([raw.step(0.0, 0.1, measurement_rate=r) for r in rates])
    b = np.array([filtered.step(0.0, 0.1, measurement_rate=r) for r in rates])
    assert b[200:].mean() == pytest.approx(-1.0, abs=0.1)  # passes the steady rate
    assert b[200:].std() < 0.5 * a[200:].std()  # and attenuates the noise


def test_steady_throttle_inverts_the_surge_balance():
    assert steady_throttle(IDENTIFIED, 1.83) == pytest.approx(42.0, abs=0.1)


def test_tracker_follows_a_dogleg_on_the_model():
    step = model.plant_step_function()
    p = IDENTIFIED.as_vector()
    path = np.array([[0, 0], [150, 0], [250, 60]], float)
    tracker = LosPidTracker(IDENTIFIED)
    tracker.set_path(path)
    x, act = np.array([0, 5.0, 0.2, 0, 0, 0]), np.zeros(2)
    xs, cmds = [], []
    for k in range(1500):
        cmd = tracker.step(x, 0.1)
        cmds.append(cmd)
        for _ in range(10):
            x, act, _ = step(x, act, cmd, p, [0, 0], [10, 40], 0.01)
        x = np.asarray(x).ravel()
        xs.append(x)
        if tracker.progress_m > 240:
            break
    xs, cmds = np.array(xs), np.array(cmds)
    assert tracker.progress_m > 240, "reached the end of the path"
    # settled on the first leg: within 0.5 m of it and at 2 m/s
    first = xs[(xs[:, 0] > 80) & (xs[:, 0] < 140)]
    assert np.abs(first[:, 1]).max() < 0.5
    assert first[:, 3] == pytest.approx(2.0, abs=0.05)
    rates = np.abs(np.diff(cmds, axis=0)) / 0.1
    assert rates[:, 0].max() <= 10.0 + 1e-9 and rates[:, 1].max() <= 40.0 + 1e-9
