"""A heading bias of the autopilot's EKF (issue 37, 1): through the bridge, on the simulated
autopilot with its EKF noise, a constant 2 degree bias leaves the boat on its line as well as
no bias does, and the current handed to the NMPC along the boat stays near zero through the
start (the navigation's noise was read as a head current of 0.3-0.45 m/s)."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np
import pytest

from bridge.shared.ardupilot import SITL_DEFAULT_HOME
from bridge.autopilot_sim.ekf import EkfModel, NoiseSpec
from bridge.lidar import SimLidarSource
from bridge.onboard.loop import BridgeOptions, OnboardLoop
from bridge.onboard.step_log import StepLog
from controller.nmpc.reference import waypoint_path
from scenarios.loop.controllers import NmpcController
from scenarios.scenario_file import load_scenario

from .rigs import SimRig

ROOT = Path(__file__).resolve().parents[2]


def _drive(tmp_path, bias_deg: float, wander_deg: float = 0.0, name: str = "straight"):
    """A scenario file through the bridge; (true cross-track per step, steps.csv rows)."""
    scenario = load_scenario(ROOT / "scenarios" / f"{name}.toml")
    rig = SimRig(scenario, tmp_path, seed=4, ekf_delay_s=5.0,
                 ekf_noise=NoiseSpec(heading_bias_rad=math.radians(bias_deg),
                                     heading_wander_sigma_rad=math.radians(wander_deg)))
    sim, link = rig.autopilot, rig.link
    truth = {}
    rig.clock.add_peer(lambda now: truth.__setitem__(round(sim.boot_s, 2), sim.true_state[:2]))
    log = StepLog(tmp_path)
    loop = OnboardLoop(link, scenario, NmpcController(scenario), SimLidarSource(scenario, seed=4),
                       BridgeOptions(mode="MANUAL", arm=True, duration_s=scenario.duration_s,
                                     ekf_timeout_s=30.0, origin=SITL_DEFAULT_HOME),
                       console=io.StringIO(), log=log)
    try:
        result = loop.run()
    finally:
        log.close()
        rig.close()
    assert result.reached_goal, result
    rows = [r for r in csv.DictReader(open(tmp_path / "steps.csv")) if r["x_m"]]
    true_xy = np.array([truth[round(float(r["ekf_time_s"]), 2)] for r in rows])
    _, d = waypoint_path(scenario.waypoints).frame_numpy(true_xy)
    return d, rows


def _column(rows, name):
    return np.array([float(r[name]) for r in rows])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["straight", "sbend"])
def test_a_heading_bias_leaves_no_steady_offset_and_no_start_up_current(tmp_path, name):
    """Issue 37's bar: mean true cross-track over the last two thirds at most 0.15 m above
    the unbiased run, with a constant 2 degree bias and with a 0.5 degree wander; no
    current above 0.05 m/s handed over in the first 30 s where the water is still and the
    heading true on average (across the boat a constant bias's stand-in, about
    u sin 2 deg = 0.07 m/s, is what removes the offset, and is handed over as it should)."""
    d0, rows0 = _drive(tmp_path / "none", 0.0, name=name)
    xt0 = float(np.abs(d0[len(d0) // 3:]).mean())
    for label, bias, wander in (("constant", 2.0, 0.0), ("wandering", 0.0, 0.5)):
        d, rows = _drive(tmp_path / label, bias, wander, name=name)
        xt = float(np.abs(d[len(d) // 3:]).mean())
        assert xt <= xt0 + 0.15, (label, xt0, xt)
        t, psi = _column(rows, "time_s"), _column(rows, "psi_rad")
        n, e = _column(rows, "current_used_n_mps"), _column(rows, "current_used_e_mps")
        along = n * np.cos(psi) + e * np.sin(psi)
        assert np.abs(along[t < 30]).max() <= 0.05, label
        if bias == 0.0:
            assert np.hypot(n, e)[t < 30].max() <= 0.05, label
    t0 = _column(rows0, "time_s")
    used0 = np.hypot(_column(rows0, "current_used_n_mps"), _column(rows0, "current_used_e_mps"))
    assert used0[t0 < 30].max() <= 0.05  # (one window of sway noise was handed over as 0.07)


def test_the_bias_is_in_the_heading_and_nowhere_else():
    """The EKF's heading carries the bias (constant plus a seeded wander of its own); the
    other errors of a seed are those without it."""
    plain = EkfModel(3, 0.0)
    biased = EkfModel(3, 0.0, NoiseSpec(heading_bias_rad=math.radians(2.0),
                                        heading_wander_sigma_rad=math.radians(0.5)))
    state = (1.0, 2.0, 0.3, 2.0, 0.1, 0.01)
    for _ in range(500):
        plain.step(0.01)
        biased.step(0.01)
    a, b = plain.estimate(state), biased.estimate(state)
    assert (a.north_m, a.east_m, a.vn_mps, a.ve_mps, a.r_radps) == \
        (b.north_m, b.east_m, b.vn_mps, b.ve_mps, b.r_radps)
    offset = (b.psi_rad - a.psi_rad + math.pi) % (2 * math.pi) - math.pi
    assert offset == pytest.approx(biased.heading_bias_rad)
    assert abs(offset - math.radians(2.0)) <= 3 * math.radians(0.5)
    assert offset != pytest.approx(math.radians(2.0))  # it wanders
    with pytest.raises(ValueError, match="heading_wander_tau_s"):
        NoiseSpec(heading_wander_tau_s=0.0)
