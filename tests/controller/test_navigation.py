"""The navigation EKF against the boat model with simulated GPS and AHRS."""

import numpy as np
import pytest

from controller import model
from controller.errors import InputError
from controller.geometry import wrap_angle
from controller.navigation import NavigationFilter
from controller.params import IDENTIFIED
from scenarios.sensors import AhrsSensor, GpsSensor


def run_filter(seconds=120.0, seed=3, x0_error=(2.0, -1.5, 0.08, 0.3, 0.0, 0.0)):
    step = model.plant_step_function()
    p = IDENTIFIED.as_vector()
    x = np.array([0, 0, 0.3, 1.5, 0, 0], float)
    act = np.array([42.0, 0.0])
    nav = NavigationFilter(x + np.array(x0_error))
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


def test_same_numbers_as_filterpy_ekf():
    """The filter is filterpy's ExtendedKalmanFilter written out: bit for bit the same
    estimates and covariance, including coasting over a bad IMU sample."""
    from filterpy.kalman import ExtendedKalmanFilter

    from controller import navigation as nav_mod

    class Strapdown(ExtendedKalmanFilter):
        def predict_x(self, u=None):
            ax, ay = (0.0, 0.0) if u is None else u
            x, y, psi, su, sv, r = self.x
            dt, c, s = self._dt, np.cos(psi), np.sin(psi)
            self.x = np.array([x + dt * (c * su - s * sv), y + dt * (s * su + c * sv),
                               wrap_angle(psi + dt * r), su + dt * (ax + r * sv),
                               sv + dt * (ay - r * su), r])

    def angle_residual(a, b):
        y = np.subtract(a, b)
        y[0] = wrap_angle(y[0])
        return y

    cfg = nav_mod.NavConfig()
    x0 = np.array([1.0, 2.0, 3.1, 1.5, 0.1, 0.02])
    nav = NavigationFilter(x0, cfg)
    ref = Strapdown(dim_x=6, dim_z=2)
    ref.x, ref.P = x0.copy(), nav.covariance
    rng = np.random.default_rng(5)
    for k in range(2000):
        dt = 0.01
        acc = rng.normal(0, 0.3, 2) if k != 777 else np.array([np.nan, 0.1])
        heading, rate = rng.uniform(-np.pi, np.pi), rng.normal(0, 0.1)
        nav.predict(dt, acc)
        psi, u, v, r = ref.x[2], ref.x[3], ref.x[4], ref.x[5]
        c, s = np.cos(psi), np.sin(psi)
        F = np.eye(6)
        F[0, 2:5] = dt * np.array([-s * u - c * v, c, -s])
        F[1, 2:5] = dt * np.array([c * u - s * v, s, c])
        F[2, 5] = dt
        F[3, 4], F[3, 5] = dt * r, dt * v
        F[4, 3], F[4, 5] = -dt * r, -dt * u
        G = np.zeros((6, 3))
        G[0, 0], G[0, 1] = 0.5 * dt**2 * c, -0.5 * dt**2 * s
        G[1, 0], G[1, 1] = 0.5 * dt**2 * s, 0.5 * dt**2 * c
        G[3, 0] = G[4, 1] = dt
        G[2, 2], G[5, 2] = 0.5 * dt**2, dt
        q_a, q_r = cfg.accel_noise_mps2**2, cfg.yaw_accel_noise_radps2**2
        ref.F, ref.Q, ref._dt = F, G @ np.diag([q_a, q_a, q_r]) @ G.T, dt
        ref.predict(u=None if k == 777 else acc)
        nav.update_ahrs(heading, rate)
        z = np.array([heading, rate])
        z[0] = ref.x[2] + wrap_angle(z[0] - ref.x[2])
        ref.update(z, lambda x: nav_mod._H_ATTITUDE, lambda x: x[[2, 5]], R=nav._R_att,
                   residual=angle_residual)
        ref.x[2] = wrap_angle(ref.x[2])
        if k % 20 == 0:
            pos, vel = rng.normal(0, 50, 2), rng.normal(0, 2, 2)
            nav.update_gps(pos, vel)
            ref.update(pos, lambda x: nav_mod._H_POSITION, lambda x: x[:2], R=nav._R_pos)
            ref.update(vel, nav_mod._H_velocity, nav_mod._h_velocity, R=nav._R_vel)
        assert nav.state.tobytes() == ref.x.tobytes(), k
        assert nav.covariance.tobytes() == ref.P.tobytes(), k
