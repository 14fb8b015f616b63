"""The plan's soft surge ceiling (issue 34): the reference's speed, or a braking line from a
boat above it, as a soft bound of the QP; a plan that raced past its reference is held to it."""

import numpy as np
import pytest

from controller.errors import InputError
from controller.nmpc.bench import BenchVessel, bend_canal, closed_loop
from controller.nmpc.controller import NmpcController
from controller.nmpc.hpipm_qp import (SET_BOUNDS, SET_CONSTRAINTS, SET_DYNAMICS, SET_GRADIENT,
                                      HpipmOcpQp)
from controller.nmpc.problem import NmpcConfig, surge_cap


def test_the_ceiling_is_the_reference_or_the_braking_line_never_below_zero_plus_the_margin():
    rng = np.random.default_rng(3)
    for _ in range(50):
        ref = rng.uniform(-1.0, 3.0, 26)
        u0, step, margin, decel = rng.uniform(-1, 4), rng.uniform(0.1, 1.0), 0.2, 0.1
        expected = [max(ref[k], u0 - decel * step * k, 0.0) + margin for k in range(26)]
        assert np.allclose(surge_cap(ref, u0, step, margin, decel), expected)
        out = np.empty(26)
        surge_cap(ref, u0, step, margin, decel, out=out)
        assert np.allclose(out, expected)


def _pulled_qp(bound_l1, general_soft):
    """x1 = u0 (x0 = 0), the cost pulling x1 to 5, x1 <= 1 a soft bound, and one general
    row x1 >= -3 (hard, or soft with the obstacle rows' price)."""
    qp = HpipmOcpQp(1, 1, 1, 1, np.array([0], np.intc), np.array([0], np.intc),
                    np.array([1.0, 1.0]), np.array([1e-6]),
                    soft_l1=1e5 if general_soft else 0.0, soft_l2=1.0 if general_soft else 0.0,
                    soft_bounds=[0], soft_bound_l1=bound_l1, soft_bound_l2=1e-3)
    qp.A[:], qp.B[:], qp.b[:] = 1.0, 1.0, 0.0
    qp.q[1] = -5.0  # 1/2 x^2 - 5 x: least at 5
    qp.lbu[:], qp.ubu[:] = -10.0, 10.0
    qp.lbx[1], qp.ubx[1] = -1e4, 1.0
    qp.C[1], qp.lg[1], qp.ug[1] = 1.0, -3.0, 1e4
    qp.set(SET_DYNAMICS | SET_CONSTRAINTS | SET_BOUNDS | SET_GRADIENT)
    status, _ = qp.solve()
    assert status == 0
    return float(qp.x[1, 0]), float(qp.bound_slack[1, 0])


@pytest.mark.parametrize("general_soft", [False, True])
def test_a_soft_bound_holds_where_its_price_is_above_the_pull_and_gives_where_not(general_soft):
    x, over = _pulled_qp(1e3, general_soft)  # the pull at the bound is 4 per unit: it holds
    assert abs(x - 1.0) < 1e-3 and over < 1e-3
    x, over = _pulled_qp(1.0, general_soft)  # at 1 per unit it gives until the pull is 1
    assert abs(x - 4.0) < 0.05 and abs(over - (x - 1.0)) < 1e-3


def test_a_boat_above_its_reference_brakes_along_a_line_kept_from_step_to_step():
    """Held above its reference (it did not slow down), the boat's braking line still goes
    down in real time: its ceiling is not drawn afresh from its surge each step."""
    c = NmpcController(NmpcConfig(surge_margin_mps=0.2), method="rti")
    ref = np.full(26, 1.0)
    out = np.empty(26)
    c._surge_cap(ref, 2.0, 0.1, out)
    assert out[0] == pytest.approx(2.2) and out[5] == pytest.approx(2.2 - 0.5)
    for _ in range(10):  # a second at 2 m/s
        c._surge_cap(ref, 2.0, 0.1, out)
    assert out[0] == pytest.approx(2.2 - 0.1 * 1.0)
    c._surge_cap(ref, 1.1, 0.1, out)  # within the margin of the reference: drawn afresh
    assert out[0] == pytest.approx(1.3) and out[3] == pytest.approx(1.2)


def _two_vessels_run(margin):
    canal = bend_canal(narrow_m=9.0)
    vessels = (BenchVessel(1, (70.0, -3.0), (-1.5, 0.0)),
               BenchVessel(2, (25.0, 30.0), (0.0, -1.0), 9.0, 3.0))
    controller = NmpcController(NmpcConfig(surge_margin_mps=margin), method="rti")
    return closed_loop(controller, canal, np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0]),
                       np.array([47.0, 0.0]), steps=600, speed_mps=2.0, vessels=vessels)


@pytest.mark.slow  # two 60 s closed loops (about 20 s): the default tests keep the QP's
# own check and case 15's regression
def test_a_boat_backed_off_for_a_vessel_comes_on_at_its_target_not_in_a_sprint():
    """The bench's two vessels: the boat gives way to a launch crossing, backs off from a
    tour boat met 3 m off the middle, and comes on again. Without the ceiling its plan
    chased the reference's progress at 3.5 m/s for a target of 2; with it, at most 0.2 over."""
    held, free = _two_vessels_run(0.2), _two_vessels_run(None)
    assert not held.failure and not free.failure
    assert held.states[:, 3].max() <= 2.0 + 0.2 + 0.05
    assert free.states[:, 3].max() > 3.0


@pytest.mark.parametrize("field, value", [("surge_margin_mps", -0.1), ("surge_l1", -1.0),
                                          ("surge_decel_mps2", 0.0)])
def test_bad_surge_settings_are_named(field, value):
    with pytest.raises(InputError, match=field):
        NmpcConfig(**{field: value})
