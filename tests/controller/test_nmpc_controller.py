"""The NMPC in closed loop on the smooth model: clearance, the narrow stretch, speed, bounds,
cold start, the code cache, bad input and failure handling (issue 5, "Must show")."""

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from controller.errors import InputError, SolverError
from controller.nmpc.problem import NmpcConfig
from controller.nmpc.bench import closed_loop, open_water, straight_canal
from controller.nmpc.controller import NmpcController
from controller.nmpc.rti import QpOptions, QpStepResult

CFG = NmpcConfig()
SAFE = CFG.hull_radius_m + CFG.separation_m  # 5 m
X0 = np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0])
ACT0 = np.array([47.0, 0.0])  # about 2 m/s steady


@pytest.fixture(scope="module")
def rti():
    return NmpcController(CFG, method="rti")


def check_bounds(run, cfg=CFG):
    """Commands and plans inside |n| <= 100 %, and commands move at most the rate limits;
    the plan itself asked for no more (the controller never had to clip its first move)."""
    tol = 1e-6
    assert not any(s.stats.command_clipped for s in run.steps)
    cmds = np.array([s.command for s in run.steps])
    assert np.all(np.abs(cmds[:, 0]) <= cfg.nT_max + tol)
    assert np.all(np.abs(cmds[:, 1]) <= cfg.nS_max + tol)
    rates = (cmds - run.actuators[:-1]) / cfg.control_period_s
    assert np.all(np.abs(rates[:, 0]) <= cfg.dnT_max + 1e-6)
    assert np.all(np.abs(rates[:, 1]) <= cfg.dnS_max + 1e-6)
    for s in run.steps:
        assert np.all(np.abs(s.states[:, 6]) <= cfg.nT_max + 1e-3)
        assert np.all(np.abs(s.states[:, 7]) <= cfg.nS_max + 1e-3)
        assert np.all(np.abs(s.inputs[:, 0]) <= cfg.dnT_max + 1e-3)
        assert np.all(np.abs(s.inputs[:, 1]) <= cfg.dnS_max + 1e-3)
        assert np.all(s.slack_m <= 1e-6) and np.all(s.slack_m >= cfg.slack_min_m - 1e-6)


def test_waypoints_near_a_wall_keep_the_hull_circles_off_it(rti):
    """Straight canal 20 m wide, waypoints 3 m from the east wall, walls in 20 m pieces: the
    circles keep R_b + d_p less the super-ellipse's error near segment ends (0.7 m)."""
    rti.reset()
    canal = straight_canal(width_m=20.0, waypoint_offset_m=7.0, piece_m=20.0)
    run = closed_loop(rti, canal, X0, ACT0, steps=350)
    assert not run.failure
    settled = run.clearance_m[150:]
    worst = float(run.clearance_m.min())
    print(f"\nworst hull-circle clearance {worst:.3f} m (R_b + d_p = {SAFE} m); "
          f"settled mean {settled.mean():.3f} m; max slack "
          f"{max(s.max_slack_m for s in run.steps):.3f} m")
    assert worst >= SAFE - 0.7
    # it does give up the waypoints to keep clear: the boat sits well west of them
    assert run.states[150:, 1].max() < 7.0 - 1.0
    assert all(s.stats.ok for s in run.steps)
    check_bounds(run)


def test_narrow_stretch_keeps_to_the_middle_and_the_slack_absorbs_it(rti):
    """9 m wide, below 2 (R_b + d_p) = 10 m: no solver failure, the slack takes the 0.5 m."""
    rti.reset()
    canal = straight_canal(width_m=9.0, waypoint_offset_m=0.0)
    x0 = X0.copy()
    x0[1] = 1.0  # start 1 m off the centre line
    run = closed_loop(rti, canal, x0, ACT0, steps=300)
    assert not run.failure
    assert all(s.stats.ok for s in run.steps)
    offset = np.abs(run.states[100:, 1])
    slack = np.array([s.max_slack_m for s in run.steps[100:]])
    print(f"\nnarrow 9 m: max offset {offset.max():.3f} m, slack {slack.min():.3f}.."
          f"{slack.max():.3f} m, clearance {run.clearance_m[100:].min():.3f} m")
    assert offset.max() < 0.5
    assert slack.min() > 0.3  # the unavoidable 0.5 m is taken by the slack
    check_bounds(run)


def test_straight_water_holds_the_target_speed(rti):
    rti.reset()
    x0 = X0.copy()
    x0[3] = 1.2
    run = closed_loop(rti, open_water(), x0, np.array([30.0, 0.0]), steps=400)
    u = run.states[250:, 3]
    print(f"\nopen water: speed {u.min():.3f}..{u.max():.3f} m/s (target 2.0)")
    assert np.all(np.abs(u - 2.0) < 0.1)
    assert np.abs(run.states[250:, 1]).max() < 0.1  # and on the line
    check_bounds(run)


def test_cold_start_converges_and_matches_ipopt():
    """A first solve from nothing (SQP to convergence) reaches the same plan as IPOPT."""
    canal = straight_canal(width_m=16.0, waypoint_offset_m=1.0)
    segs = canal.segments()
    sqp = NmpcController(CFG, method="sqp")
    first = sqp.step(X0, ACT0, segs, canal.waypoints, 2.0)
    assert first.stats.ok and first.stats.converged
    ipopt = NmpcController(CFG, method="ipopt")
    ref = ipopt.step(X0, ACT0, segs, canal.waypoints, 2.0)
    assert ref.stats.ok
    assert np.abs(first.states[:, :2] - ref.states[:, :2]).max() < 0.05
    assert np.abs(first.command - ref.command).max() < 0.05
    rti = NmpcController(CFG, method="rti")
    assert rti.step(X0, ACT0, segs, canal.waypoints, 2.0).stats.ok


@pytest.mark.parametrize("current", [(0.0, 0.0), (0.0, 0.3), (0.3, 0.0)])
def test_a_boat_at_rest_between_walls_starts_cleanly(current):
    """From rest with the throttle at 0: the first guess must give the QP thrust to work
    with (thrust goes with nT |nT|), else every QP fails."""
    canal = straight_canal(width_m=16.0)
    ctl = NmpcController(CFG, max_failures=1)
    run = closed_loop(ctl, canal, np.zeros(6), np.zeros(2), steps=100, current=current)
    assert not run.failure and all(s.stats.ok for s in run.steps)
    assert run.states[-1, 3] > 0.5  # under way
    check_bounds(run)


_CACHE_PROBE = (
    "import json, warnings; warnings.simplefilter('error', RuntimeWarning); "
    "from controller.nmpc import NmpcController; "
    "c = NmpcController(); i = c.compiled_info; "
    "print(json.dumps({'hit': i.cache_hit, 'lib': str(i.library), 'compile_s': i.compile_s, "
    "'hpipm_hit': c._qp.qp.cache_hit}))")


def test_a_cold_cache_compiles_once_and_a_second_process_compiles_nothing(tmp_path):
    """Two processes on an empty cache folder: the first compiles the linearisation and the
    HPIPM shim, the second finds both and leaves the folder untouched."""
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path)}

    def probe():
        out = subprocess.run([sys.executable, "-c", _CACHE_PROBE], capture_output=True,
                             text=True, check=True, env=env)
        return json.loads(out.stdout.strip().splitlines()[-1])

    first = probe()
    assert first["hit"] is False and first["hpipm_hit"] is False and first["compile_s"] > 0
    library = Path(first["lib"])
    assert library.parent == tmp_path / "canalnav"
    files = {p.name: p.stat().st_mtime_ns for p in library.parent.iterdir()}
    second = probe()
    assert second == {"hit": True, "lib": str(library), "compile_s": 0.0, "hpipm_hit": True}
    assert {p.name: p.stat().st_mtime_ns for p in library.parent.iterdir()} == files


def test_a_cached_library_is_used_without_a_compiler(rti, monkeypatch):
    """A boat computer may carry the cache but no gcc: the libraries load all the same."""
    from controller.nmpc import codegen_cache

    assert rti.compiled_info.compiled
    monkeypatch.setattr(codegen_cache, "compiler", lambda: None)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        ctl = NmpcController(CFG)
    assert ctl.compiled_info.compiled and ctl.compiled_info.cache_hit
    assert ctl._qp.options.solver == "hpipm"


def test_no_compiler_falls_back_to_interpreted_functions(monkeypatch, tmp_path):
    from controller.nmpc import codegen_cache

    monkeypatch.setattr(codegen_cache, "compiler", lambda: None)
    ocp_fn = NmpcController(CFG, method="ipopt").ocp.linearisation
    with pytest.warns(RuntimeWarning, match="interpreted"):
        info = codegen_cache.compile_cached(ocp_fn, directory=tmp_path)
    assert not info.compiled and info.function is ocp_fn and not list(tmp_path.iterdir())


def test_with_no_compiler_and_an_empty_cache_the_controller_runs_interpreted(monkeypatch,
                                                                            tmp_path):
    from controller.nmpc import codegen_cache

    monkeypatch.setattr(codegen_cache, "compiler", lambda: None)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    with pytest.warns(RuntimeWarning) as caught:
        ctl = NmpcController(CFG)
    text = " ".join(str(w.message) for w in caught)
    assert "interpreted" in text and "CasADi's" in text  # the linearisation and the QP
    assert not ctl.compiled_info.compiled
    canal = straight_canal(width_m=20.0)
    assert ctl.step(X0, ACT0, canal.segments(), canal.waypoints, 2.0).stats.ok


def _tiny_function():
    import casadi as ca

    x = ca.SX.sym("x", 2)
    return ca.Function("tiny", [x], [x * x])


def _break_the_cached_library(fn, directory):
    from controller.nmpc import codegen_cache

    broken = codegen_cache.library_path(fn.name(), codegen_cache.generate_c(fn),
                                        directory=directory)
    broken.parent.mkdir(parents=True, exist_ok=True)
    broken.write_bytes(b"not a shared library")
    return broken


def test_a_cached_library_that_does_not_load_is_rebuilt(tmp_path):
    from controller.nmpc import codegen_cache

    fn = _tiny_function()
    broken = _break_the_cached_library(fn, tmp_path)
    info = codegen_cache.compile_cached(fn, directory=tmp_path)
    assert info.compiled and not info.cache_hit and info.library == broken
    assert float(info.function([3.0, 4.0])[1]) == 16.0


def test_without_a_compiler_a_library_that_does_not_load_falls_back(tmp_path, monkeypatch):
    from controller.nmpc import codegen_cache

    fn = _tiny_function()
    _break_the_cached_library(fn, tmp_path)
    monkeypatch.setattr(codegen_cache, "compiler", lambda: None)
    with pytest.warns(RuntimeWarning, match="cannot compile or load"):
        info = codegen_cache.compile_cached(fn, directory=tmp_path)
    assert not info.compiled and info.function is fn


@pytest.mark.parametrize("field, value, words", [
    ("state", [0, float("nan"), 0, 2, 0, 0], "NaN"),
    ("state", [0, 0, 0], "6 numbers"),
    ("state", np.zeros((2, 3)), r"shape \(2, 3\)"),
    ("target_speed_mps", "fast", "target_speed_mps: expected a number, got 'fast'"),
    ("target_speed_mps", None, "target_speed_mps: expected a number"),
    ("target_speed_mps", 1e6, r"top speed at 100 % throttle\), got 1e\+06"),
    ("target_speed_mps", -1.0, "target_speed_mps: must lie in"),
    ("elapsed_s", "x", "elapsed_s: expected a number"),
    ("elapsed_s", -0.1, "elapsed_s: must be a non-negative"),
    ("waypoints", [], "empty"),
    ("segments", [[10.0, 5.0, 0.0, 0.0]], "zero or negative length"),
    ("actuators", [float("inf"), 0], "NaN or infinity"),
])
def test_bad_input_is_a_clear_error(rti, field, value, words):
    args = {"state": X0, "actuators": ACT0, "segments": np.zeros((0, 4)),
            "waypoints": [[0.0, 0.0], [100.0, 0.0]], "target_speed_mps": 2.0}
    rti.reset()
    args[field] = value
    with pytest.raises(InputError, match=words):
        rti.step(**args)


def test_negative_weight_is_a_clear_error():
    with pytest.raises(InputError, match="negative"):
        NmpcController(NmpcConfig(r_diag=(1.0, -1.0)))


@pytest.mark.parametrize("rows", ["hard", "exact-penalty"])
def test_a_failing_qp_falls_back_then_reports_failure(rows):
    """hpipm stopped after one iteration: never passed on, shifted plan, then SolverError
    (with elastic obstacle rows too: a QP that cannot finish is a numerical fault)."""
    canal = straight_canal(width_m=20.0)
    segs = canal.segments()
    cfg = NmpcConfig(obstacle_rows=rows)
    good = NmpcController(cfg, max_failures=3)
    first = good.step(X0, ACT0, segs, canal.waypoints, 2.0)
    assert first.stats.ok
    # same controller state, a QP solver that cannot finish (nor its elastic twin)
    bad = NmpcController(cfg, qp=QpOptions(iter_max=1))._qp
    good._qp.qp, good._qp.elastic_qp = bad.qp, bad.elastic_qp
    x, act = X0.copy(), first.command
    x[0] += 0.2
    second = good.step(x, act, segs, canal.waypoints, 2.0)
    assert not second.stats.ok and second.stats.fallback == "shifted_plan"
    assert "max_iter" in second.stats.status
    assert second.stats.consecutive_failures == 1
    # the command follows the previous plan shifted by 0.1 s
    assert np.allclose(second.rates, first.inputs[0] + 0.1 * (first.inputs[1] - first.inputs[0]))
    assert np.all(np.isfinite(second.command))
    third = good.step(x, second.command, segs, canal.waypoints, 2.0)
    assert third.stats.consecutive_failures == 2
    with pytest.raises(SolverError, match="3 steps in a row"):
        good.step(x, third.command, segs, canal.waypoints, 2.0)


def test_a_cold_start_that_fails_holds_the_actuators_then_reports_failure():
    """With no solved plan to follow, a failed solve is not passed on either: the actuators
    are held (rates 0), the step says so, and the third failure in a row raises."""
    canal = straight_canal(width_m=20.0)
    segs = canal.segments()
    ctl = NmpcController(CFG, qp=QpOptions(iter_max=1), max_failures=3)
    act = np.array([30.0, 5.0])
    for k in (1, 2):
        step = ctl.step(X0, act, segs, canal.waypoints, 2.0)
        assert not step.stats.ok and step.stats.fallback == "hold"
        assert step.stats.consecutive_failures == k
        assert np.array_equal(step.command, act) and np.array_equal(step.rates, [0.0, 0.0])
        assert np.all(step.states[:, 6:8] == act)
    with pytest.raises(SolverError, match="3 steps in a row"):
        ctl.step(X0, act, segs, canal.waypoints, 2.0)


def test_a_failed_warm_start_is_retried_from_the_safe_guess(monkeypatch):
    canal = straight_canal(width_m=20.0)
    segs = canal.segments()
    ctl = NmpcController(CFG)
    first = ctl.step(X0, ACT0, segs, canal.waypoints, 2.0)
    calls = []

    def fail_once(original):  # the first QP of the step fails, whichever phase solves it
        def wrapped(self, *args):
            r = original(self, *args)
            calls.append(r.ok)
            if len(calls) == 1:
                return QpStepResult(r.dw * np.nan, False, "forced", 0, 0.0, 0.0)
            return r
        return wrapped

    monkeypatch.setattr(type(ctl._qp), "solve", fail_once(type(ctl._qp).solve))
    monkeypatch.setattr(type(ctl._qp), "feedback", fail_once(type(ctl._qp).feedback))
    second = ctl.step(X0, first.command, segs, canal.waypoints, 2.0)
    assert second.stats.ok and second.stats.fallback == "safe_guess"
    assert len(calls) == 2 and ctl.consecutive_failures == 0


@pytest.mark.parametrize("garbage", ["nan", "past_bounds"])
def test_a_fed_back_step_that_is_not_finite_or_breaks_bounds_is_not_taken(monkeypatch, garbage):
    """The feedback checks the step with the OCP's box (x_0's the state's) and the step's
    size from the HPIPM shim: a QP that claims success with garbage is a failed step."""
    from controller.nmpc.bench import closed_loop, bend_canal

    canal = bend_canal()
    ctl = NmpcController(CFG)
    ubw = ctl._ubw.copy()
    closed_loop(ctl, canal, X0, ACT0, steps=3, scan_ahead=True)  # a prepared step next
    original = type(ctl._qp).feedback
    seen = []

    def spoil(self, *args):
        r = original(self, *args)
        dw = r.dw.copy()
        at = ctl.ocp.states_at[3, 3]  # u at stage 3: bounded
        dw[at] = np.nan if garbage == "nan" else ubw[at] + 1.0 - args[0][at]
        seen.append(at)
        norm = float(np.abs(dw).max())
        return QpStepResult(dw, True, r.status, r.qp_iterations, 0.0, 0.0, norm)

    monkeypatch.setattr(type(ctl._qp), "feedback", spoil)
    state, act = X0.copy(), ACT0.copy()
    step = ctl.feedback(state, act, canal.segments(), canal.waypoints, 2.0)
    assert seen, "the prepared step was fed back"
    assert step.stats.fed_back
    assert step.stats.fallback == "safe_guess"  # the spoiled step was refused, then retried
    assert np.isfinite(step.command).all()


def test_the_shims_largest_entry_is_numpys():
    """The step's size found in C as HPIPM's solution is copied out equals numpy's
    max |dw| over the same solution (its twin), NaN passed on."""
    canal = straight_canal(width_m=20.0)
    ctl = NmpcController(CFG)
    for _ in range(3):
        st = ctl.step(X0, ACT0, canal.segments(), canal.waypoints, 2.0)
    qp = ctl._qp.qp
    numpy_twin = max(np.abs(qp.x).max(), np.abs(qp.u).max())
    assert qp.largest_entry() == numpy_twin > 0.0
    assert st.stats.ok


def test_rti_stays_within_0_2_m_of_converged_sqp_on_the_bend():
    from controller.nmpc.bench import bend_canal

    canal = bend_canal()  # as `canalnav bench nmpc`: 600 steps reach the 9 m stretch
    runs = {m: closed_loop(NmpcController(CFG, method=m), canal, X0, ACT0, steps=600)
            for m in ("rti", "sqp")}
    d = np.hypot(*(runs["rti"].states[:, :2] - runs["sqp"].states[:, :2]).T)
    print(f"\nRTI vs SQP: max {d.max():.4f} m")
    assert d.max() < 0.2


def test_without_the_direct_hpipm_interface_casadis_is_used(monkeypatch):
    from controller.nmpc import hpipm_qp

    def no_build(*args, **kwargs):
        raise OSError("no C compiler found")

    monkeypatch.setattr(hpipm_qp, "load_library", no_build)
    with pytest.warns(RuntimeWarning, match="CasADi's"):
        ctl = NmpcController(CFG)
    assert ctl._qp.options.solver == "hpipm-casadi"
    canal = straight_canal(width_m=20.0)
    step = ctl.step(X0, ACT0, canal.segments(), canal.waypoints, 2.0)
    assert step.stats.ok


def test_the_split_step_gives_the_unsplit_answer_and_feeds_back_from_the_preparation():
    """prepare/feedback (what step does) against one-phase RTI: the same plans, the
    feedback uses the prepared QP, and a changed segment set is linearised anew."""
    canal = straight_canal(width_m=20.0)
    segs = canal.segments()
    split, plain = NmpcController(CFG, split=True), NmpcController(CFG, split=False)
    x, act = X0.copy(), ACT0.copy()
    for k in range(6):
        if k == 4:
            segs = segs[:-2]  # two segments fewer: other slots than prepared
        a = split.feedback(x, act, segs, canal.waypoints, 2.0)
        split.prepare()
        b = plain.step(x, act, segs, canal.waypoints, 2.0)
        assert a.stats.ok and b.stats.ok
        assert np.abs(a.states - b.states).max() < 1e-6
        assert a.stats.fed_back == (k > 0) and not b.stats.fed_back
        assert a.stats.time_feedback_s > 0 and (k == 0 or a.stats.time_preparation_s > 0)
        x = b.states[1] * 0.1 + b.states[0] * 0.9  # somewhere along the plan, not on it
        x, act = x[:6].copy(), b.command


def test_the_split_step_keeps_the_unsplit_answer_when_the_first_move_meets_its_rate_limit():
    """A target speed that drops to 0 and comes back drives dnT_0 to its bounds: the
    prepared QP must bound u_0 around the guess's u_0, not around the one of the last full
    solve (the prepared step once broke the rate limit and fell back to a safe guess)."""
    canal = straight_canal(width_m=20.0)
    segs = canal.segments()
    split, plain = NmpcController(CFG, split=True), NmpcController(CFG, split=False)
    x, act = X0.copy(), ACT0.copy()
    at_limit = 0
    for k in range(30):
        speed = 2.0 if k < 5 or k >= 20 else 0.0
        a = split.step(x, act, segs, canal.waypoints, speed)
        b = plain.step(x, act, segs, canal.waypoints, speed)
        assert a.stats.ok and b.stats.ok and not a.stats.fallback
        assert a.stats.fed_back == (k > 0)
        # the prepared step's reference is made at the state the plan predicted, the
        # one-phase step's at the state given: close, not equal
        assert np.abs(a.states - b.states).max() < 1e-2
        assert np.abs(a.command - b.command).max() < 1e-2
        at_limit += abs(b.rates[0]) >= CFG.dnT_max - 1e-6
        x, act = b.states[1, :6] * 0.1 + b.states[0, :6] * 0.9, b.command
    assert at_limit >= 5  # the case this test is about: dnT_0 on its bound


def test_a_step_set_up_in_the_preparation_only_embeds_its_state():
    """With the preparation's inputs the feedback sets nothing up (no reference, slots or
    linearisation of its own) and its plan stays close to the one-phase step's while the
    state given strays from the predicted one; a changed input is set up at the state, and
    the preparation after it only linearises until the inputs repeat."""
    canal = straight_canal(width_m=20.0)
    segs = canal.segments()
    split, plain = NmpcController(CFG, split=True), NmpcController(CFG, split=False)
    calls = []
    setup = split._setup
    split._setup = lambda *a, **k: calls.append(1) or setup(*a, **k)
    rng = np.random.default_rng(3)
    x, act = X0.copy(), ACT0.copy()
    worst = 0.0  # the plans' difference over the state's from the predicted one
    stray = 0.0
    for k in range(14):
        speed = 1.5 if k == 6 else 2.0  # a new speed: set up anew in steps 6 and 7, and in
        # 8, whose preparation (after 7, unlike 6) only linearised; as in step 1
        before = len(calls)
        a = split.feedback(x, act, segs, canal.waypoints, speed)
        made = len(calls) - before
        split.prepare()
        b = plain.step(x, act, segs, canal.waypoints, speed)
        assert a.stats.ok and b.stats.ok and not a.stats.fallback
        assert a.stats.set_up_in_preparation == (k not in (0, 1, 6, 7, 8))
        assert made == (0 if a.stats.set_up_in_preparation else 1)
        if a.stats.set_up_in_preparation:
            apart = float(np.abs(a.states[:, :2] - b.states[:, :2]).max())
            worst = max(worst, apart / stray)
        x = b.states[1, :6] * 0.1 + b.states[0, :6] * 0.9  # the prediction, then astray
        noise = rng.normal(0.0, 0.05, 2)
        x[:2] += noise
        stray = float(np.hypot(*noise))
        act = b.command
    print(f"\nprepared setup vs one-phase: plans apart by at most {worst:.2f} x the stray")
    assert worst < 2.0


def test_a_scan_handed_to_the_preparation_lets_the_feedback_only_embed_the_state():
    """Segments that arrive after the command go into `prepare(segments=...)`: the next
    feedback with them is set up already; without them it sets itself up."""
    canal = straight_canal(width_m=20.0)
    segs = canal.segments()
    newer = segs[:-1]  # a scan later: one piece fewer
    for handed in (False, True):
        ctl = NmpcController(CFG)
        ctl.feedback(X0, ACT0, segs, canal.waypoints, 2.0)
        ctl.prepare(segments=newer if handed else None)
        step = ctl.feedback(X0 + [0.2, 0, 0, 0, 0, 0], ACT0, newer, canal.waypoints, 2.0)
        assert step.stats.ok and step.stats.fed_back
        assert step.stats.set_up_in_preparation == handed
    with pytest.raises(InputError, match="segments"):
        ctl.prepare(segments=np.zeros((2, 3)))
