"""The NMPC's obstacle rows as an exact penalty (issue 34): feasible whatever the rows ask,
the hard QP's answer where that one is feasible, the violation reported."""

import numpy as np
import pytest

from controller.errors import InputError, SolverError
from controller.nmpc.bench import closed_loop, straight_canal
from controller.nmpc.controller import NmpcController
from controller.nmpc.problem import NmpcConfig

X0 = np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0])
ACT0 = np.array([47.0, 0.0])
WAYPOINTS = np.array([[0.0, 0.0], [200.0, 0.0]])
# A wall across the way 6 m ahead and one along the hull, through its circles: no plan can
# keep R_b + d_p, nor the least margin the stage slack allows (0.1 m), at stage 1.
IMPOSSIBLE = np.array([[6.0, 0.0, np.pi / 2, 30.0], [0.0, 0.5, 0.0, 20.0]])


def controller(rows):
    return NmpcController(NmpcConfig(obstacle_rows=rows), method="rti")


def test_rows_no_plan_can_keep_fail_the_hard_qp_and_not_the_exact_penalty():
    hard, soft = controller("hard"), controller("exact-penalty")
    with pytest.raises(SolverError, match="steps in a row"):
        for _ in range(3):
            hard.step(X0, ACT0, IMPOSSIBLE, WAYPOINTS, 2.0)
    for _ in range(5):
        st = soft.step(X0, ACT0, IMPOSSIBLE, WAYPOINTS, 2.0)
        assert st.stats.ok and not st.stats.fallback
    assert st.stats.elastic_segments > 0.1  # the rows were violated, and it says how far
    assert st.stats.elastic_vessels < 1e-6  # (no vessel)


@pytest.mark.parametrize("width_m", [20.0, 11.0])
def test_where_the_hard_qp_is_feasible_the_answer_is_the_same(width_m):
    """A canal with the waypoints 3 m off a wall (20 m), and one narrower than 2 (R_b + d_p)
    (11 m, the stage slack at work): 300 steps with each, positions within 1 cm."""
    canal = straight_canal(width_m=width_m, waypoint_offset_m=3.0 if width_m > 15 else 0.0,
                           piece_m=20.0)
    runs = [closed_loop(controller(rows), canal, X0, ACT0, steps=300)
            for rows in ("hard", "exact-penalty")]
    assert not runs[0].failure and not runs[1].failure
    assert np.abs(runs[0].states[:, :2] - runs[1].states[:, :2]).max() < 0.01
    assert max(s.stats.elastic_segments for s in runs[1].steps) < 1e-4


@pytest.mark.parametrize("field, value", [("obstacle_rows", "soft"), ("obstacle_l1", -1.0),
                                          ("obstacle_l1", 0.0)])
def test_bad_penalty_settings_are_named(field, value):
    with pytest.raises(InputError, match=field):
        NmpcConfig(**{field: value})


def test_per_row_penalties_choose_which_row_gives():
    """Two soft rows no point satisfies (x >= 1 and x <= -1 at stage 1): with equal
    penalties the answer splits the violation; with the second row at a tenth (the vessel
    rows' share), the first holds and the second gives."""
    import numpy as np

    from controller.nmpc.hpipm_qp import (SET_BOUNDS, SET_CONSTRAINTS, SET_DYNAMICS,
                                          SET_GRADIENT, HpipmOcpQp)

    def solve(share):
        qp = HpipmOcpQp(1, 1, 1, 2, np.array([], np.intc), np.array([0], np.intc),
                        np.array([1e-6, 1e-6]), np.array([1e-6]), soft_l1=1e3, soft_l2=1.0)
        qp.soft_weights(1e3 * np.array([1.0, share]), np.array([1.0, share]))
        qp.A[:] = 1.0  # x1 = x0 + u0, x0 = 0
        qp.B[:] = 1.0
        qp.b[:] = 0.0
        qp.lbu[:], qp.ubu[:] = -10.0, 10.0
        qp.C[1] = [1.0, -1.0]  # rows: x1 >= 1 and -x1 >= 1
        qp.lg[1] = [1.0, 1.0]
        qp.ug[1] = [1e4, 1e4]
        qp.set(SET_DYNAMICS | SET_CONSTRAINTS | SET_BOUNDS | SET_GRADIENT)
        status, _ = qp.solve()
        assert status == 0
        return float(qp.x[1, 0])

    assert abs(solve(1.0)) < 0.1  # both violated by about 1
    assert solve(0.1) > 0.9  # the cheaper row gives: x1 at the first row's bound
