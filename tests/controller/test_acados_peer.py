"""The acados peer of `bench nmpc`: its per-stage parameters and warm start match what
canalnav's controller gives its own QP, a missing wheel is one clear error, and (where the
wheel is installed beside the project) the peer follows canalnav's trajectory."""

import numpy as np
import pytest

from controller.errors import InputError
from controller.nmpc.acados_peer import peer_environment, shifted, stage_params, wheel_dir
from controller.nmpc.bench import bend_canal, closed_loop
from controller.nmpc.controller import NmpcController
from controller.nmpc.problem import NmpcConfig, ParamLayout, pack_params
from controller.nmpc.rti import QpOptions


def test_stage_params_split_canalnav_parameters_per_stage_and_free_stage_zero():
    c = NmpcConfig(segment_slots=3, vessel_slots=2, horizon=4)
    rng = np.random.default_rng(0)
    segs = np.column_stack([rng.normal(size=(3, 4)), np.ones(3)])
    vessels = np.concatenate([rng.normal(size=(4, 2, 5)), np.ones((4, 2, 1))], axis=2)
    p = pack_params(c, segs, current=(0.1, -0.2), bias=(0.01, 0.0, 0.0), vessel_slots=vessels)
    lay = ParamLayout.of(c)
    out = stage_params(c, p)
    assert out.shape == (5, lay.segments.stop + 2 * 6)
    for k in range(1, 5):  # stage k: the shared part, then stage k's vessel slots
        np.testing.assert_array_equal(out[k, : lay.segments.stop], p[: lay.segments.stop])
        np.testing.assert_array_equal(out[k, lay.segments.stop:], vessels[k - 1].ravel())
    # stage 0: every slot inactive (its state is fixed; no obstacle rows there), the rest kept
    assert (out[0, lay.segments][4::5] == 0).all() and (out[0, lay.segments.stop:][5::6] == 0).all()
    np.testing.assert_array_equal(out[0, : lay.segments.start], p[: lay.segments.start])


def test_shifted_plan_is_the_controllers_shift():
    c = NmpcConfig(horizon=6, segment_slots=2, vessel_slots=0)
    controller = NmpcController(c, method="rti", qp=QpOptions())
    rng = np.random.default_rng(1)
    w = rng.normal(size=controller.ocp.nw)
    controller._plan = w
    for elapsed in (0.1, 0.35, 1.0):
        expected = controller._shifted_plan(elapsed)
        xs, us = w[controller.ocp.states_at], w[controller.ocp.inputs_at]
        x, u = shifted(xs, us, elapsed, c.step_s)
        np.testing.assert_allclose(x, expected[controller.ocp.states_at], rtol=0, atol=1e-12)
        np.testing.assert_allclose(u, expected[controller.ocp.inputs_at], rtol=0, atol=1e-12)


def test_missing_acados_wheel_is_one_error_naming_the_install(monkeypatch, tmp_path):
    monkeypatch.setenv("CANALNAV_HPIPM_DIR", str(tmp_path / "nothing"))
    with pytest.raises(InputError, match="comma-deps-acados"):
        peer_environment()


def test_recorded_inputs_are_what_the_ocp_was_given():
    c = NmpcConfig()
    record = []
    controller = NmpcController(c, method="rti", qp=QpOptions())
    x0, act0 = np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0]), np.array([47.0, 0.0])
    run = closed_loop(controller, bend_canal(), x0, act0, 5, record=record)
    assert len(record) == len(run.steps) == 5
    cpu, x_init, p, w_ref, guess = record[0]
    assert cpu > 0 and guess is not None  # the first step's guess: the safe guess
    np.testing.assert_array_equal(x_init, np.concatenate([x0, act0]))
    assert p.shape == (ParamLayout.of(c).size,) and w_ref.shape == (controller.ocp.nw,)
    # the reference's first stage is where the boat is on the path
    assert np.hypot(*(w_ref[controller.ocp.states_at[0][:2]] - x0[:2])) < 1.0


def _installed() -> bool:
    try:
        peer_environment()
        return True
    except InputError:
        return False


@pytest.mark.slow
@pytest.mark.skipif(not _installed(), reason=f"comma-deps-acados is not installed in {wheel_dir()}")
def test_acados_follows_canalnavs_trajectory_within_a_centimetre(capsys):
    import json

    from bridge.main import main

    assert main(["bench", "nmpc", "--steps", "150", "--solvers", "rti", "--no-unsplit-peer",
                 "--vessel-steps", "0", "--qp-compare-steps", "0", "--peer", "acados",
                 "--peer-repeats", "1"]) == 0
    peer = json.loads(capsys.readouterr().out)["peer_acados"]
    assert peer["acados"]["failed_steps"] == 0 and peer["canalnav"]["failed_steps"] == 0
    assert peer["max_position_diff_m"] <= 0.01
    assert peer["goal"]["trajectory<=0.01m"] is True


def test_scan_ahead_sets_every_step_up_in_the_preparation_and_keeps_the_track():
    """With the walls of one step handed to the next step's preparation, the feedback only
    embeds the state (the latency acados is compared on); the track moves by well under a
    millimetre, as the walls within 50 m move by one period's travel."""
    c = NmpcConfig()
    x0, act0 = np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0]), np.array([47.0, 0.0])
    runs = {}
    for ahead in (False, True):
        controller = NmpcController(c, method="rti", qp=QpOptions())
        runs[ahead] = closed_loop(controller, bend_canal(), x0, act0, 120, scan_ahead=ahead)
    prepared = [s.stats.set_up_in_preparation for s in runs[True].steps]
    assert all(prepared[1:]) and not prepared[0]
    assert sum(s.stats.set_up_in_preparation for s in runs[False].steps) < len(prepared) - 5
    d = np.hypot(*(runs[True].states[:, :2] - runs[False].states[:, :2]).T)
    assert d.max() < 1e-3
