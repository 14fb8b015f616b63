"""The OCP as built: config checks, segment slots, the obstacle constraint, the Jacobian."""

import math

import casadi as ca
import numpy as np
import pytest

from controller.errors import InputError
from controller.nmpc.problem import NmpcConfig, build_ocp, clearance_function, pack_params
from controller.nmpc.segment_slots import check_segments, fill_segment_slots, select_segments


@pytest.fixture(scope="module")
def ocp():
    return build_ocp(NmpcConfig())


def test_one_ocp_per_config_in_a_process_and_it_cannot_be_changed(ocp):
    from controller.nmpc.codegen_cache import compile_cached

    assert build_ocp(NmpcConfig()) is ocp  # built once: controllers share it
    assert build_ocp(NmpcConfig(horizon=20)) is not ocp
    with pytest.raises(ValueError, match="read-only"):
        ocp.states_at[0, 0] = 1  # a controller writing into it would change every other's
    first = compile_cached(ocp.first_stage)
    assert compile_cached(ocp.first_stage) is first  # its C not generated again


def test_config_defaults_are_the_papers_table():
    c = NmpcConfig()
    assert (c.horizon, c.step_s, c.control_period_s) == (25, 1.0, 0.1)
    assert c.q_diag == (1, 1, 500, 10, 0, 1000, 0, 0) and c.r_diag == (1, 1)
    assert np.allclose(c.Q_T, 25 * c.Q) and c.slack_weight == 1e4
    assert (c.nT_max, c.nS_max, c.dnT_max, c.dnS_max) == (100, 100, 10, 40)
    assert (c.hull_radius_m, c.hull_offsets_m, c.separation_m) == (3.0, (2.0, -2.0), 2.0)
    # the slack gives up the separation d_p, never the hull circle's own radius (the room
    # the passage rule gives the hull: 2 R_b); a smaller floor may be asked for
    assert c.slack_min_m == pytest.approx(-2.0)
    assert NmpcConfig(separation_m=4.0).slack_min_m == pytest.approx(-4.0)
    assert NmpcConfig(min_half_axis_m=0.1).slack_min_m == pytest.approx(-4.9)
    assert NmpcConfig(separation_m=0.0).slack_min_m == 0.0


@pytest.mark.parametrize("changes, words", [
    ({"q_diag": (1, 1, 500, -10, 0, 1000, 0, 0)}, "negative"),
    ({"r_diag": (1.0, -1.0)}, "negative"),
    ({"slack_weight": -1.0}, "slack_weight"),
    ({"q_diag": (1, 1, 500)}, "8 weights"),
    ({"q_diag": (1, 1, 500, float("nan"), 0, 1000, 0, 0)}, "finite"),
    ({"horizon": 0}, "positive integer"),
    ({"dnT_max": 0.0}, "positive"),
    ({"control_period_s": 2.0}, "step_s"),
    ({"min_half_axis_m": 6.0}, "min_half_axis"),
    ({"min_half_axis_m": 0.0}, "min_half_axis"),
    ({"slack_weight": [1e4]}, "'slack_weight': expected a number"),
    ({"horizon": "25"}, "expected numbers"),
])
def test_bad_config_is_a_clear_error(changes, words):
    """Each a clear InputError; numpy numbers and lists of weights are fine (below)."""
    with pytest.raises(InputError, match=words):
        NmpcConfig(**changes)


def test_slots_hold_the_nearest_segments_then_inactive_padding():
    segs = np.array([[0, 30, 0, 10], [0, 5, 0, 10], [0, -12, 0, 10], [0, 80, 0, 10]], float)
    slots = fill_segment_slots(segs, [0, 0], n_slots=4, range_m=50.0)
    assert slots[:, 1].tolist() == [5, -12, 30, 0]  # nearest first; the 80 m one dropped
    assert slots[:, 4].tolist() == [1, 1, 1, 0]
    assert np.all(slots[3] == 0)
    many = np.column_stack([np.zeros(20), np.arange(20.0) + 1, np.zeros(20), np.ones(20)])
    assert fill_segment_slots(many, [0, 0], n_slots=16)[:, 1].tolist() == list(range(1, 17))
    assert fill_segment_slots(np.zeros((0, 4)), [0, 0], n_slots=3).sum() == 0


def test_slots_prefer_the_walls_along_the_planned_path_to_those_behind():
    """Wall pieces every 10 m from 60 m behind to 50 m ahead, both sides of a canal heading
    north: ranked by distance to the planned path (50 m ahead), the slots keep the pieces
    alongside the plan and drop those behind the stern; the step says what it dropped."""
    x = np.arange(-55.0, 50.0, 10.0)
    segs = np.vstack([np.column_stack([x, np.full(len(x), side), np.zeros(len(x)),
                                       np.full(len(x), 10.0)]) for side in (-8.0, 8.0)])
    plan = np.column_stack([np.linspace(0.0, 50.0, 26), np.zeros(26)])
    sel = select_segments(segs, [0, 0], n_slots=10, range_m=60.0, path=plan)
    kept = sel.slots[sel.slots[:, 4] > 0]
    # alongside the plan, nearer the boat first: the pieces centred at -5 .. 35 m each side
    assert sorted(kept[:, 0].tolist()) == sorted([-5.0, 5.0, 15.0, 25.0, 35.0] * 2)
    assert sel.dropped == len(segs) - 10
    assert sel.dropped_nearest_m == pytest.approx(8.0)  # the 45 m pieces alongside, left out
    by_boat = select_segments(segs, [0, 0], n_slots=10, range_m=60.0)
    assert by_boat.slots[:, 0].min() < -10.0  # ranked from the boat: pieces behind the stern
    assert select_segments(segs[:4], [0, 0], n_slots=10, path=plan).dropped == 0


def test_config_takes_numpy_numbers_and_lists_of_weights():
    c = NmpcConfig(q_diag=[1, 1, 500, 10, 0, 1000, 0, 0], horizon=np.int64(20),
                   step_s=np.float32(1.0), r_diag=np.array([1.0, 2.0]))
    assert c.q_diag == (1, 1, 500, 10, 0, 1000, 0, 0) and c.r_diag == (1.0, 2.0)
    assert c.horizon == 20 and hash(c) is not None


@pytest.mark.parametrize("segments, words", [
    ([[0, 0, 0, 0.0]], "zero or negative length"),
    ([[0, 0, 0, 5.0], [1, 1, 0, -2.0]], "row 1"),
    ([[0, float("nan"), 0, 5.0]], "not finite"),
    ([[0, 0, 5.0]], "shape"),
])
def test_bad_segments_are_clear_errors(segments, words):
    with pytest.raises(InputError, match=words):
        check_segments(segments)


def test_clearance_is_the_papers_super_ellipse_with_the_slack_on_both_axes():
    """Sign of h equals the sign of eq. mpc:pnorm with the slack shrinking both half axes (so a
    segment's ends are soft too); an inactive slot gives h = 1."""
    cfg = NmpcConfig(segment_slots=2, vessel_slots=0)
    h = clearance_function(cfg)
    rng = np.random.default_rng(1)
    Rb, dp = cfg.hull_radius_m, cfg.separation_m
    seg = (3.0, -2.0, 0.4, 12.0)
    slots = np.array([[*seg, 1.0], [0, 0, 0, 0, 0.0]]).T
    for _ in range(200):
        x = np.zeros(9)
        x[:3] = rng.uniform(-15, 15), rng.uniform(-15, 15), rng.uniform(-math.pi, math.pi)
        x[8] = rng.uniform(cfg.slack_min_m, 0)
        vals = np.array(h(x, slots, [Rb, dp, 2.0, -2.0, 2.0], np.zeros((6, 0)))).ravel()
        for k, d in enumerate((2.0, -2.0)):
            px, py = x[0] + d * math.cos(x[2]), x[1] + d * math.sin(x[2])
            dx, dy = px - seg[0], py - seg[1]
            X = (dx * math.cos(seg[2]) + dy * math.sin(seg[2])) / (seg[3] / 2 + Rb + dp + x[8])
            Y = (-dx * math.sin(seg[2]) + dy * math.cos(seg[2])) / (Rb + dp + x[8])
            paper = X**4 + Y**4 - 1
            if abs(paper) > 1e-6:
                assert np.sign(vals[2 * k]) == np.sign(paper)
            assert vals[2 * k + 1] == 1.0  # the inactive slot


def test_constraint_rows_follow_hpipms_stage_order(ocp):
    """gap_0, (gap_k, h_k) for k = 1..N-1, then h_N; equality rows are the gaps."""
    N, nx, nh = ocp.N, ocp.n_gap, ocp.n_h
    gaps = ocp.gap_rows()
    assert ocp.ng == N * nx + N * nh and gaps.sum() == N * nx
    assert gaps[:nx].all()
    assert gaps[nx:2 * nx].all() and not gaps[2 * nx:2 * nx + nh].any()
    assert not gaps[-nh:].any()
    s = ocp.hpipm_structure()
    assert s["nu"][-1] == 0 and len(s["nu"]) == N + 1 and s["ng"][0] == 0


def test_assembled_jacobian_equals_casadis(ocp):
    cfg = ocp.config
    segs = np.array([[30, 8, 0.1, 40], [30, -8, -0.1, 40], [60, 0, 1.2, 8]])
    p = pack_params(cfg, fill_segment_slots(segs, [0, 0], cfg.segment_slots), (0.2, -0.1))
    w = np.random.default_rng(3).normal(size=ocp.nw)
    pieces = [np.asarray(v).ravel(order="F") for v in ocp.linearisation(w, p)]
    g, jac_nz = ocp.assemble(*pieces)
    W = ca.MX.sym("w", ocp.nw)
    ref = ca.Function("ref", [W], [ocp.constraints(W, p), ca.jacobian(ocp.constraints(W, p), W)])
    g_ref, J_ref = ref(w)
    assert np.allclose(g, np.asarray(g_ref).ravel(), atol=1e-12)
    J = ca.DM(ocp.jac_sparsity, jac_nz)
    assert float(ca.mmax(ca.fabs(J - J_ref))) < 1e-9


def test_the_ocps_dynamics_are_the_smooth_models_rk4(ocp):
    """f_d is the one model's smooth variant, RK4 in the configured sub-steps over Ts; the
    actuator states integrate the rates, and the next slack is the input sigma."""
    from controller.model import Variant, step_function

    cfg = ocp.config
    boat = step_function(cfg.step_s, cfg.rk4_substeps, Variant(smooth=True, eps=cfg.smooth_eps))
    p = cfg.boat.as_vector()
    x = np.array([3.0, -2.0, 0.3, 1.8, 0.05, -0.02, 42.0, 15.0, -0.4])
    held = np.asarray(ocp.dynamics(x, [0.0, 0.0, -0.7], p, [0.2, -0.1], [0, 0, 0])).ravel()
    ref = np.asarray(boat(x[:6], x[6:8], p, [0.2, -0.1])).ravel()
    assert np.allclose(held[:6], ref, rtol=0, atol=1e-12)
    assert held[6:8].tolist() == [42.0, 15.0] and held[8] == -0.7
    moved = np.asarray(ocp.dynamics(x, [3.0, -5.0, 0.0], p, [0.0, 0.0], [0, 0, 0])).ravel()
    assert np.allclose(moved[6:8], [45.0, 10.0])
    assert not np.allclose(moved[:6], held[:6])  # the moving actuators act within the step
