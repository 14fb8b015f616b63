"""The simulated identification runs: the paper's programme, steady states, zigzag logic, seeds."""

import math

import numpy as np
import pytest

from controller.identification import maneuvers as m
from controller.params import IDENTIFIED


@pytest.fixture(scope="module")
def exact():
    return m.generate(seed=3, noise="none", runs=m.QUICK_RUNS)


def test_same_seed_same_logs_other_seed_other_noise():
    runs = (m.QUICK_RUNS[2],)
    a = m.generate(seed=5, runs=runs)["03_zigzag_20_50"]
    b = m.generate(seed=5, runs=runs)["03_zigzag_20_50"]
    c = m.generate(seed=6, runs=runs)["03_zigzag_20_50"]
    np.testing.assert_array_equal(a.states, b.states)
    assert not np.allclose(a.states, c.states)


def test_realistic_noise_has_the_stated_sizes(exact):
    noisy = m.generate(seed=3, noise="realistic", runs=m.QUICK_RUNS)
    err = noisy["01_acceleration"].states - exact["01_acceleration"].states
    expected = m.SensorNoise().sigmas()
    np.testing.assert_allclose(err.std(axis=0), expected, rtol=0.1)


def test_paper_programme_and_truth_in_the_header():
    names = [r.name for r in m.PAPER_RUNS]
    assert m.PAPER_RUNS[0].throttle_pct == (31.0, 34.9, 38.6, 41.0, 50.6)
    assert (m.PAPER_RUNS[1].start_pct, m.PAPER_RUNS[1].throttle_pct) == (50.6, (39.4, 20.0))
    zig, held = m.PAPER_RUNS[2], m.PAPER_RUNS[3]
    assert (zig.heading_deg, zig.steering_pct, zig.throttle_pct, zig.overshoots) == (20, 50, 42, 3)
    assert (held.heading_deg, held.steering_pct, held.use) == (10, 30, "heldout")
    assert len(set(names)) == len(names)


def test_surge_steps_are_held_to_steady_state(exact):
    log = exact["01_acceleration"]
    nT = log.commands[:, 0]
    assert log.time_s[1] - log.time_s[0] == pytest.approx(m.SAMPLE_S)
    assert nT.max() == pytest.approx(50.6) and np.all(log.commands[:, 1] == 0)
    # the rate limit: throttle moves at most 10 %/s
    assert np.abs(np.diff(nT)).max() <= m.THROTTLE_RATE_PCT_S * m.SAMPLE_S + 1e-9
    # before each step up the speed had settled
    steps = np.flatnonzero(np.diff(nT) > 0)
    starts = [s for s in steps if s == 0 or nT[s] == nT[s - 1]]
    for s in starts[1:]:
        window = log.states[s - 50:s, 3]
        assert np.ptp(window) < 0.03
    assert log.states[-1, 3] == pytest.approx(2.25, abs=0.03)  # DESIGN: 2.25 m/s at 50.6 %
    dec = exact["02_deceleration"]
    assert dec.states[0, 3] == pytest.approx(2.25, abs=0.03) and dec.states[-1, 3] < 0.9


def test_zigzag_reverses_at_the_heading_limit_and_stops_after_three_overshoots(exact):
    log = exact["03_zigzag_20_50"]
    psi, nS = np.degrees(log.states[:, 2]), log.commands[:, 1]
    assert log.meta["maneuver"] == "zigzag" and log.commands[0, 0] == pytest.approx(42.0)
    # first order to starboard (nS < 0: the heading grows), then three reversals at +-20 deg;
    # a reversal order is where the logged steering leaves its +-50 % plateau (rate-limited)
    first = np.flatnonzero(nS)[0]
    assert nS[first] < 0
    reversals = [s for s in range(len(nS) - 1) if abs(nS[s]) == 50.0 and nS[s + 1] != nS[s]]
    assert len(reversals) == 3
    for s in reversals:
        assert abs(psi[s]) == pytest.approx(20.0, abs=1.0)
    # three overshoot peaks beyond +-20 deg, and the run stops soon after the third
    r = log.states[:, 5]
    peaks = np.flatnonzero(np.diff(np.sign(r)) != 0)
    peaks = [p for p in peaks if abs(psi[p]) > 20.0]
    assert len(peaks) == 3
    assert log.time_s[-1] - log.time_s[peaks[-1]] < 3.0


def test_heldout_run_is_tagged(exact):
    assert exact["04_heldout_zigzag_10_30"].heldout
    assert not exact["03_zigzag_20_50"].heldout
    assert exact["03_zigzag_20_50"].truth() == IDENTIFIED


def test_unknown_noise_is_refused():
    from controller.errors import InputError

    with pytest.raises(InputError, match="noise 'loud'"):
        m.generate(noise="loud", runs=m.QUICK_RUNS[:1])


def test_write_logs_names_files_after_runs(tmp_path, exact):
    paths = m.write_logs(tmp_path / "logs", exact)
    assert sorted(p.name for p in paths) == sorted(f"{k}.csv" for k in exact)
    assert math.isfinite(float(paths[0].read_text().splitlines()[-1].split(",")[0]))


def test_overshoots_lengthen_the_fit_zigzag_only(exact):
    from controller.errors import InputError

    runs = m.with_overshoots(m.QUICK_RUNS, 6)
    assert [r.overshoots for r in runs if isinstance(r, m.ZigzagRun)] == [6, 2]  # held-out kept
    assert m.with_overshoots(m.QUICK_RUNS, None) == m.QUICK_RUNS
    longer = m.generate(seed=3, noise="none", runs=(runs[2],))["03_zigzag_20_50"]
    short = exact["03_zigzag_20_50"]
    assert longer.time_s[-1] - longer.time_s[0] > 1.8 * (short.time_s[-1] - short.time_s[0])
    reversals = np.count_nonzero(np.diff(np.sign(longer.commands[:, 1][longer.commands[:, 1] != 0])))
    assert reversals >= 6
    for bad in (0, 51, 2.5):
        with pytest.raises(InputError, match="--overshoots"):
            m.with_overshoots(m.QUICK_RUNS, bad)
