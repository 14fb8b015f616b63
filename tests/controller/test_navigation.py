"""The navigation EKF against the boat model with simulated GPS and AHRS."""

import numpy as np
import pytest

from controller import model
from controller.errors import InputError
from controller.geometry import wrap_angle
from controller.navigation import NavigationFilter
from controller.params import IDENTIFIED
from scenarios.sensors.gps_ahrs import AhrsSensor, GpsSensor


def run_filter(seconds=120.0, seed=3, x0_error=(2.0, -1.5, 0.08, 0.3, 0.0, 0.0),
               backend="auto", covariances=None):
    step = model.plant_step_function()
    p = IDENTIFIED.as_vector()
    x = np.array([0, 0, 0.3, 1.5, 0, 0], float)
    act = np.array([42.0, 0.0])
    nav = NavigationFilter(x + np.array(x0_error), backend=backend)
    gps, ahrs = GpsSensor(seed=seed), AhrsSensor(seed=seed + 1)
    errors = []
    for k in range(int(seconds * 100)):
        t = k * 0.01
        cmd = [42.0, 40.0 * np.sign(np.sin(2 * np.pi * t / 40.0))]  # zigzag
        x, act, xdot = (np.asarray(a).ravel() for a in step(x, act, cmd, p, [0.2, 0.1], [10, 40], 0.01))
        sample = ahrs.measure(x, xdot)
        nav.predict(0.01, sample.accel_body)
        nav.update_ahrs(sample.heading_rad, sample.yaw_rate_radps)
        if k % 20 == 0:
            fix = gps.measure(x)
            nav.update_gps(fix.position_ne, fix.velocity_ne)
        if covariances is not None:
            covariances.append(nav.covariance)
        e = nav.state - x
        e[2] = wrap_angle(e[2])
        errors.append(e)
    return np.array(errors)


def test_filter_converges_and_tracks_a_zigzag_in_a_current():
    err = run_filter()
    late = np.abs(err[len(err) // 2:])
    assert late[:, 0].max() < 0.1 and late[:, 1].max() < 0.1  # m
    assert late[:, 2].max() < np.radians(0.5)
    assert late[:, 3].max() < 0.1 and late[:, 4].max() < 0.1  # m/s
    assert late[:, 5].max() < np.radians(0.5)
    # and the start error has been removed quickly
    assert np.abs(err[300, :2]).max() < 0.2


def test_compiled_filter_matches_its_filterpy_reference():
    """The C kernel against filterpy's EKF with the same model: a zigzag across north's
    wrap of the heading, GPS at 5 Hz, 60 s; states and covariances within rounding."""
    pc, pf = [], []
    c = run_filter(60.0, seed=5, backend="c", covariances=pc)
    f = run_filter(60.0, seed=5, backend="filterpy", covariances=pf)
    assert np.abs(c - f).max() < 1e-9
    assert np.abs(np.array(pc) - np.array(pf)).max() < 1e-12


@pytest.mark.parametrize("backend", ["c", "filterpy"])
def test_heading_wraps_alike_in_both_backends(backend):
    nav = NavigationFilter([0, 0, np.pi - 0.001, 0, 0, 0.5], backend=backend)
    for _ in range(10):
        nav.predict(0.01, [0.0, 0.0])
        nav.update_ahrs(wrap_angle(np.pi + 0.004), 0.5)
    assert -np.pi <= nav.state[2] < -np.pi + 0.05  # turned past north, wrapped


def test_unknown_backend_is_named():
    with pytest.raises(InputError, match="backend"):
        NavigationFilter([0, 0, 0, 0, 0, 0], backend="fortran")


def test_same_seed_same_estimate():
    a, b = run_filter(10.0, seed=7), run_filter(10.0, seed=7)
    assert np.array_equal(a, b)


def test_heading_update_across_north_wraps():
    nav = NavigationFilter([0, 0, np.pi - 0.01, 0, 0, 0])
    nav.update_ahrs(-np.pi + 0.01, 0.0)
    assert abs(wrap_angle(nav.state[2] - np.pi)) < 0.02


def test_non_finite_measurements_are_skipped_not_fused():
    nav = NavigationFilter([1, 2, 0.1, 1, 0, 0])
    before = nav.state
    nav.update_gps([np.nan, 0.0], [np.inf, 0.0])
    nav.update_ahrs(np.nan, 0.0)
    nav.predict(0.1, [np.nan, 0.0])
    assert np.all(np.isfinite(nav.state))
    assert nav.state[0] == pytest.approx(before[0] + 0.1 * np.cos(0.1))  # coasted, not fused


def test_bad_initial_state_is_named():
    with pytest.raises(InputError, match="initial state"):
        NavigationFilter([0, 0, np.nan, 0, 0, 0])
