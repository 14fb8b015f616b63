"""The boat model's sanity figures (DESIGN.md, issue "Boat model") and its variants."""

import math

import casadi as ca
import numpy as np
import pytest

from controller import model
from controller.params import IDENTIFIED, PARAM_NAMES, BoatParams

P = IDENTIFIED.as_vector()


def simulate(cmd, seconds, x0=None, current=(0.0, 0.0), variant=model.EXACT, params=P):
    step = model.step_function(0.1, 1, variant)
    x = np.zeros(6) if x0 is None else np.asarray(x0, float)
    for _ in range(int(round(seconds / 0.1))):
        x = np.asarray(step(x, cmd, params, current)).ravel()
    return x


def test_steady_surge_at_42_percent_is_1_83_mps():
    x = simulate([42.0, 0.0], 600.0)
    assert x[3] == pytest.approx(1.83, rel=0.02)
    assert abs(x[4]) < 1e-9 and abs(x[5]) < 1e-9 and abs(x[2]) < 1e-9


def test_positive_steering_turns_to_port_and_settles_near_minus_0_064():
    x = simulate([42.0, 50.0], 300.0, x0=[0, 0, 0, 1.83, 0, 0])
    assert x[5] < 0, "nS > 0 must give a negative (port) yaw rate"
    assert x[5] == pytest.approx(-0.064, abs=0.002)
    # settled: the yaw rate no longer changes
    later = simulate([42.0, 50.0], 10.0, x0=x)
    assert later[5] == pytest.approx(x[5], abs=1e-5)


def test_negative_steering_mirrors_positive():
    port = simulate([42.0, 30.0], 60.0, x0=[0, 0, 0, 1.5, 0, 0])
    stbd = simulate([42.0, -30.0], 60.0, x0=[0, 0, 0, 1.5, 0, 0])
    assert stbd[5] == pytest.approx(-port[5], rel=1e-9)
    assert stbd[1] == pytest.approx(-port[1], rel=1e-9)


def test_current_from_astern_drifts_the_boat_at_current_speed():
    # Heading north, current flowing north (from astern) at 0.5 m/s, no thrust.
    x = simulate([0.0, 0.0], 900.0, current=(0.5, 0.0))
    assert x[3] == pytest.approx(0.5, rel=0.01)
    before = x[0]
    x = simulate([0.0, 0.0], 10.0, x0=x, current=(0.5, 0.0))
    assert (x[0] - before) / 10.0 == pytest.approx(0.5, rel=0.01)


def test_cross_current_sets_the_boat_sideways_over_ground():
    # Heading north, current flowing east: at rest in the water the boat moves east over ground.
    x = simulate([0.0, 0.0], 900.0, current=(0.0, 0.4))
    assert x[4] == pytest.approx(0.4, rel=0.01)
    assert abs(x[3]) < 1e-6


def test_reverse_thrust_is_negative():
    x = simulate([-42.0, 0.0], 300.0)
    assert x[3] < -1.0


def test_smooth_variant_is_close_to_exact_away_from_zero():
    f_exact, f_smooth = model.ode_function(model.EXACT), model.ode_function(model.SMOOTH)
    x = [0, 0, 0.3, 1.5, 0.2, -0.05]
    a = np.asarray(f_exact(x, [40, 20], P, [0.1, -0.2])).ravel()
    b = np.asarray(f_smooth(x, [40, 20], P, [0.1, -0.2])).ravel()
    np.testing.assert_allclose(a, b, rtol=2e-3, atol=1e-4)
    # and it is differentiable at zero velocity, where the exact model has a kink
    xs = ca.SX.sym("x", 6)
    J = ca.Function("J", [xs], [ca.jacobian(model.boat_ode(xs, [0, 0], P, (0, 0), model.SMOOTH), xs)])
    assert np.all(np.isfinite(np.asarray(J(np.zeros(6)))))


def test_parameters_are_symbolic_inputs():
    f = model.ode_function()
    heavy = IDENTIFIED.replace(m11=2 * IDENTIFIED.m11).as_vector()
    a = np.asarray(f([0, 0, 0, 1, 0, 0], [42, 0], P, [0, 0])).ravel()
    b = np.asarray(f([0, 0, 0, 1, 0, 0], [42, 0], heavy, [0, 0])).ravel()
    assert b[3] == pytest.approx(a[3] / 2)


def test_equations_unchanged_when_all_parameters_scale_together():
    x = simulate([42.0, 30.0], 50.0, x0=[0, 0, 0, 1.0, 0, 0])
    y = simulate([42.0, 30.0], 50.0, x0=[0, 0, 0, 1.0, 0, 0], params=IDENTIFIED.scaled(3.7).as_vector())
    np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-9)


def test_rk4_substeps_converge_to_fine_solution():
    x0 = [0, 0, 0, 1.0, 0, 0]
    coarse = np.asarray(model.step_function(1.0, 1)(x0, [50, 40], P, [0, 0])).ravel()
    fine = np.asarray(model.step_function(1.0, 10)(x0, [50, 40], P, [0, 0])).ravel()
    finer = np.asarray(model.step_function(1.0, 100)(x0, [50, 40], P, [0, 0])).ravel()
    assert np.abs(fine - finer).max() < np.abs(coarse - finer).max()
    assert np.abs(fine - finer).max() < 1e-6


def test_rate_limits_bound_the_actuators():
    step = model.plant_step_function()
    x, act = np.zeros(6), np.zeros(2)
    for _ in range(10):  # 1 s at 0.1 s
        x, act, _ = step(x, act, [100, -100], P, [0, 0], [10, 40], 0.1)
    act = np.asarray(act).ravel()
    assert act == pytest.approx([10.0, -40.0])
    # rate 0 switches the limit off
    _, act, _ = step(np.zeros(6), np.zeros(2), [55, 20], P, [0, 0], [0, 0], 0.1)
    assert np.asarray(act).ravel() == pytest.approx([55.0, 20.0])


def test_plant_step_reports_accelerations():
    step = model.plant_step_function()
    _, _, xdot = step([0, 0, 0, 1.0, 0, 0], [42, 0], [42, 0], P, [0, 0], [0, 0], 0.1)
    xdot = np.asarray(xdot).ravel()
    expected = (IDENTIFIED.c_eff * 42**2 + IDENTIFIED.Xu * 1.0 + IDENTIFIED.Xuu * 1.0) / IDENTIFIED.m11
    assert xdot[3] == pytest.approx(expected)


def test_parameter_vector_order_matches_names():
    assert list(IDENTIFIED.as_dict()) == list(PARAM_NAMES)
    assert BoatParams.from_vector(IDENTIFIED.as_vector()) == IDENTIFIED
    assert IDENTIFIED.c_eff == pytest.approx(0.13331)
    assert IDENTIFIED.delta_max == pytest.approx(math.radians(25))
