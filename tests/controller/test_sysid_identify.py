"""System identification on generated logs (the quick set), and its refusals."""

import dataclasses
import math

import numpy as np
import pytest

from controller.identification import maneuvers as m
from controller.identification import sysid
from controller.errors import InputError
from controller.identification.logs import read_log, write_log
from controller.params import IDENTIFIED

RATIO_5 = ("Xu", "Xuu", "c")
RATIO_10 = ("m22", "m33", "Yv", "Nr")


@pytest.fixture(scope="module")
def logs():
    """The quick runs with realistic noise, the zigzag made like a real log: no sway speed,
    yaw rate at half the rate of the rest."""
    out = m.generate(seed=1, noise="realistic", runs=m.QUICK_RUNS)
    zig = out["03_zigzag_20_50"]
    states = zig.states.copy()
    states[:, 4] = np.nan
    states[1::2, 5] = np.nan
    out["03_zigzag_20_50"] = dataclasses.replace(zig, states=states)
    return out


@pytest.fixture(scope="module")
def result(logs):
    return sysid.identify(list(logs.values()))


def ratio_error(result, name):
    return next(r.ratio_error for r in result.parameters if r.name == name)


def test_initial_guess_comes_from_the_dimensions_only():
    guess = sysid.initial_guess(sysid.BoatDimensions())
    heavier = sysid.initial_guess(sysid.BoatDimensions(mass_kg=3400.0))
    for name in ("m11", "m22", "m33", "Yv", "Nr", "Xuu", "c"):
        assert getattr(guess, name) != pytest.approx(getattr(IDENTIFIED, name), rel=0.05)
    assert heavier.m11 > guess.m11 and heavier.m33 > guess.m33
    # m11: the weight plus Soding's surge added mass, 2.7 rho V^(5/3) / L^2
    assert guess.m11 == pytest.approx(1700 + 2.7 * 1000 * 1.7 ** (5 / 3) / 7.9**2)


def test_surge_ratios_within_5_percent(result):
    assert result.anchor == "m11"
    for name in RATIO_5:
        assert abs(ratio_error(result, name)) < 0.05, name


def test_sway_yaw_ratios_within_10_percent(result):
    for name in RATIO_10:
        assert abs(ratio_error(result, name)) < 0.10, name


def test_every_estimate_has_a_standard_error_and_undetermined_terms_are_named(result):
    rows = {r.name: r for r in result.parameters}
    for name in RATIO_5 + RATIO_10:
        assert rows[name].role == "estimated"
        assert 0 < rows[name].std_error < 0.2 * abs(rows[name].estimate)
    nrr = rows["Nrr"]
    assert math.isfinite(nrr.std_error) and nrr.std_error > 0
    if nrr.role == "left out":
        assert nrr.estimate == 0.0 and "not determined" in nrr.note
    assert rows["m11"].role == "fixed" and math.isnan(rows["m11"].std_error)
    table = sysid.format_table(result)
    assert "Söding" in table and "std err" in table and "ratio err" in table


def test_heldout_run_checks_the_fit_and_never_enters_it(result):
    fitted = [name for stage in result.stages for name in stage.logs]
    assert "04_heldout_zigzag_10_30" not in fitted
    (fit,) = result.heldout
    assert fit.source == "04_heldout_zigzag_10_30"
    assert fit.heading_rms_deg < 1.0 and fit.speed_rms_mps < 0.05
    assert fit.yaw_rate_rms_degps < 0.5


def test_noise_free_logs_are_recovered_closely():
    runs = (m.QUICK_RUNS[0],)
    log = m.generate(seed=1, noise="none", runs=runs)["01_acceleration"]
    res = sysid.identify([log], sysid.SysidConfig(fixed={"m22": 1800.0}))
    for name in RATIO_5:
        assert abs(ratio_error(res, name)) < 1e-3
    assert any("no sway-yaw run" in n for n in res.notes)


def test_fixing_c_moves_the_scale_anchor():
    log = m.generate(seed=2, noise="realistic", runs=(m.QUICK_RUNS[0],))["01_acceleration"]
    res = sysid.identify([log], sysid.SysidConfig(fixed={"c": IDENTIFIED.c}))
    assert res.anchor == "c" and res.params.c == IDENTIFIED.c
    # with the true c fixed, the absolute values come out near the truth
    assert res.params.m11 == pytest.approx(IDENTIFIED.m11, rel=0.05)


def short_log(tmp_path, logs, n):
    log = logs["01_acceleration"]
    cut = dataclasses.replace(log, time_s=log.time_s[:n], states=log.states[:n],
                              commands=log.commands[:n])
    path = tmp_path / "short.csv"
    write_log(path, cut)
    return read_log(path)


def test_a_log_too_short_to_identify_anything_names_file_line_and_column(tmp_path, logs):
    short = short_log(tmp_path, logs, 5)
    with pytest.raises(InputError) as exc:
        sysid.identify([short])
    msg = str(exc.value)
    assert str(tmp_path / "short.csv") in msg and "too short" in msg
    assert "column 'u'" in msg and ":" + str(short.line_of(0)) in msg


def test_no_surge_run_is_refused(logs):
    with pytest.raises(InputError, match="no surge run"):
        sysid.identify([logs["03_zigzag_20_50"]])


def test_unknown_fixed_parameter_is_refused():
    with pytest.raises(InputError, match="--fix m44"):
        sysid.SysidConfig(fixed={"m44": 1.0})


@pytest.mark.parametrize("value", [0.0, -1.0, math.inf, math.nan])
def test_a_selection_threshold_that_is_not_a_positive_number_is_refused(value):
    with pytest.raises(InputError, match="--select-se"):
        sysid.SysidConfig(select_se=value)


@pytest.mark.slow  # (two more identifications, 19 s)
def test_the_selection_threshold_decides_which_optional_terms_stay(logs, result):
    """Each term left out by the default rule was tried from the same core fit: a threshold
    just under the largest trial t value keeps that term; one of 1e6 SE keeps none."""
    rows = {r.name: r for r in result.parameters}
    left_out = [n for n in sysid.OPTIONAL_TERMS if rows[n].role == "left out"]
    assert left_out == list(sysid.OPTIONAL_TERMS), "the default keeps no term on these logs"
    for name in left_out:
        assert f"< {sysid.SELECT_T:.3g} SE" in rows[name].note, name
    t = {}
    for name in left_out:
        value = float(rows[name].note.split("trial fit ")[1].split(" ±")[0])
        t[name] = abs(value) / rows[name].std_error
    best = max(t, key=t.get)
    looser = sysid.identify(list(logs.values()), sysid.SysidConfig(select_se=0.999 * t[best]))
    kept = {r.name: r for r in looser.parameters}
    assert kept[best].role == "estimated" and kept[best].estimate != 0.0
    for name in sysid.OPTIONAL_TERMS[:sysid.OPTIONAL_TERMS.index(best)]:
        assert kept[name].role == "left out", name
    strict = sysid.identify(list(logs.values()), sysid.SysidConfig(select_se=1e6))
    rows = {r.name: r for r in strict.parameters}
    for name in sysid.OPTIONAL_TERMS:
        assert rows[name].role == "left out" and rows[name].estimate == 0.0, name
        assert "< 1e+06 SE" in rows[name].note, name


def test_identification_is_deterministic():
    log = m.generate(seed=4, noise="realistic", runs=(m.QUICK_RUNS[1],))["02_deceleration"]
    config = sysid.SysidConfig(fixed={"m22": 1800.0})
    a, b = sysid.identify([log], config), sysid.identify([log], config)
    assert a.params == b.params
    assert [r.std_error for r in a.parameters][:9] == [r.std_error for r in b.parameters][:9]



def test_a_covariance_that_cannot_be_computed_is_unknown_not_a_traceback(monkeypatch):
    """When the information matrix cannot be decomposed (NumPy's eigh did not converge on a
    diverged trial fit of a noisy DataFlash log), the spreads are unknown (infinite) and the
    identification still ends with its table; nothing raises."""
    def fails(*_a, **_k):
        raise np.linalg.LinAlgError("Eigenvalues did not converge")

    monkeypatch.setattr(sysid, "_safe_inverse", fails)
    log = m.generate(seed=1, noise="realistic", runs=(m.QUICK_RUNS[0],))["01_acceleration"]
    res = sysid.identify([log], sysid.SysidConfig(fixed={"m22": 1800.0}))
    rows = {r.name: r for r in res.parameters}
    assert {"Xu", "Xuu", "c"} <= set(rows)
    assert all(math.isfinite(rows[n].estimate) for n in ("Xu", "Xuu", "c"))
    assert all(rows[n].std_error == math.inf for n in ("Xu", "Xuu", "c"))


def test_the_noise_model_finds_an_ar1_residual():
    """_estimate_noise on residuals that are AR(1) (rho 0.9, sigma_w 0.1) with a gap: the
    correlation and the innovation's size come back, and the weight is 1/sigma_w^2 up to the
    common scale."""
    rng = np.random.default_rng(4)
    n = 4000
    e = np.zeros(n)
    for k in range(1, n):
        e[k] = 0.9 * e[k - 1] + 0.1 * rng.standard_normal()
    white = 0.02 * rng.standard_normal(n)
    t = 0.1 * np.arange(n)
    states = np.zeros((n, 6))
    states[:, 0], states[:, 5] = e, white  # x: AR(1), r: white
    states[1000:1010, 0] = np.nan  # not measured there
    log = m.ManeuverLog(t, states, np.zeros((n, 2)), {"maneuver": "zigzag"}, source="synthetic")
    data = sysid._Data.of(log)
    zero_traj = [np.zeros((6, n))]  # the "fit": residual = -measurement
    noise = sysid._estimate_noise([data], zero_traj, list(range(6)),
                                  np.array([1.0, 0, 0, 0, 0, 1.0]), cost=1.0)
    assert set(noise) == {0, 5}
    assert noise[0].rho == pytest.approx(0.9, abs=0.02)
    assert noise[0].sigma_w == pytest.approx(0.1, rel=0.05)
    assert noise[5].rho < 0.05 and noise[5].sigma_w == pytest.approx(0.02, rel=0.05)
    assert noise[0].weight * noise[0].sigma_w**2 == pytest.approx(
        noise[5].weight * noise[5].sigma_w**2)
    assert noise[0].correlation_time(0.1) == pytest.approx(-0.1 / math.log(0.9), rel=0.2)


def test_the_time_limit_stops_with_a_clear_error(logs):
    with pytest.raises(sysid.SolverTimeLimit, match=r"time limit, 0.001 s of CPU.*--time-limit"):
        sysid.identify(list(logs.values()), sysid.SysidConfig(max_cpu_s=1e-3))
    with pytest.raises(InputError, match="--time-limit"):
        sysid.SysidConfig(max_cpu_s=0.0)


class _Burner:
    """A stand-in for a CasADi solver: `seconds` of CPU (None: forever), then an answer."""

    def __init__(self, seconds):
        self.seconds = seconds

    def __call__(self, **args):
        import time

        start = time.process_time()
        while self.seconds is None or time.process_time() - start < self.seconds:
            pass
        return {"x": np.asarray(args["x0"]) + 1.0, "f": np.array([[2.5]])}

    def stats(self):
        return {"return_status": "Solve_Succeeded", "iter_count": 3, "success": True}


def test_a_solve_is_capped_by_the_kernel_even_inside_an_iteration():
    """IPOPT checks its max_cpu_time between iterations only; the child a solve runs in is
    stopped by its CPU limit wherever it is (here a loop that never returns), and a solve
    within its time comes back from the child with its answer and stats."""
    import time

    t0 = time.perf_counter()
    sol, stats = sysid.solve_capped(_Burner(None), {"x0": np.zeros(3)}, 1.0)
    assert stats["capped"] and stats["success"] is False and sol == {}
    assert time.perf_counter() - t0 < 30.0  # (a generous bound: the machine may be busy)
    c0 = sysid.cpu_time_s()
    sol, stats = sysid.solve_capped(_Burner(0.2), {"x0": np.zeros(3)}, 10.0)
    assert sol["x"].tolist() == [1.0, 1.0, 1.0] and float(sol["f"].ravel()[0]) == 2.5
    assert stats == {"return_status": "Solve_Succeeded", "iter_count": 3, "success": True}
    assert sysid.cpu_time_s() - c0 >= 0.2  # the child's CPU counts in the budget


def _biased(log, bias_rad):
    """`log` as an EKF with a compass off by `bias_rad` records it: the heading plus the
    bias, the velocity over ground resolved along that heading."""
    states = log.states.copy()
    u, v = states[:, 3].copy(), states[:, 4].copy()
    states[:, 2] += bias_rad
    states[:, 3] = u * math.cos(bias_rad) + v * math.sin(bias_rad)
    states[:, 4] = -u * math.sin(bias_rad) + v * math.cos(bias_rad)
    return dataclasses.replace(log, states=states)


def test_the_heading_bias_measurement_model():
    """What the sway-yaw stage fits a run's bias with: the heading plus the bias, the
    velocity over ground resolved along it (2 deg at 2 m/s: a sway of -0.07 m/s)."""
    import casadi as ca

    log = m.generate(seed=2, noise="none", runs=m.QUICK_RUNS)["03_zigzag_20_50"]
    bias = math.radians(2.0)
    ours = np.asarray(sysid._as_measured(ca.DM(log.states.T), bias)).T
    np.testing.assert_allclose(ours, _biased(log, bias).states, atol=1e-12)
    straight = np.asarray(sysid._as_measured(ca.DM([0, 0, 0, 2.0, 0, 0]), bias)).ravel()
    assert straight[4] == pytest.approx(-0.0698, abs=1e-4) and straight[2] == bias


def test_the_heading_bias_can_be_left_out():
    assert sysid.SysidConfig().heading_bias
    assert not sysid.SysidConfig(heading_bias=False).heading_bias


def test_a_stage_that_does_not_converge_names_the_run_and_what_to_try(logs):
    with pytest.raises(sysid.SolverError) as err:
        sysid.identify(list(logs.values()), sysid.SysidConfig(max_iter=3))
    text = str(err.value)
    assert "did not converge (Maximum_Iterations_Exceeded, 3 iterations) on the run " in text
    assert "; try: " in text and "--window" in text
    assert any(name in text for name in logs)
