"""End to end: a scenario through the bridge's link and the simulated autopilot (mavlink-sim),
against the direct co-simulation, and over a lossy, slow link."""

import json
from pathlib import Path

import numpy as np
import pytest

from bridge.autopilot_sim.plant import LinkFaults, MavlinkSimPlant
from scenarios.loop.runner import PLANTS, run_scenario
from scenarios.scenario_file import parse_scenario


@pytest.fixture(scope="module")
def scenario(short_bend_toml):
    return parse_scenario(short_bend_toml, "short.toml")


@pytest.fixture(scope="module")
def direct(scenario, tmp_path_factory):
    return run_scenario(scenario, tmp_path_factory.mktemp("direct"), plots=False).summary


def _run(scenario, out, faults=LinkFaults()):
    PLANTS["mavlink-test"] = lambda sc, d: MavlinkSimPlant(sc, d, faults=faults)
    try:
        return run_scenario(scenario, out, plant="mavlink-test", plots=False).summary
    finally:
        del PLANTS["mavlink-test"]


def test_mavlink_run_matches_the_direct_cosimulation(scenario, direct, tmp_path):
    s = _run(scenario, tmp_path)
    assert direct["reached_goal"] and s["reached_goal"] and not s["collision"], s
    # The controller sees the autopilot's EKF (0.2 m, 0.3 deg of wandering error) and its
    # commands land one autopilot tick later; on this short scenario's sharp bend (30 m radius)
    # that moves the minimum by about 0.6 m (0.45 m without the EKF noise). On the default
    # scenario the two agree within 0.1 m (the slow test below; the issue asks for 0.5 m).
    assert abs(s["min_clearance_m"] - direct["min_clearance_m"]) <= 0.8, (s, direct)
    tlog = (tmp_path / "mavlink.tlog").read_bytes()
    assert len(tlog) > 10_000 and tlog[8] == 0xFD  # timestamped MAVLink 2 frames
    rows = (tmp_path / "log.csv").read_text().splitlines()
    assert len(rows) == s["steps"] + 1
    est = np.array([[float(v) for v in r.split(",")[7:9]] for r in rows[1:]])
    true = np.array([[float(v) for v in r.split(",")[1:3]] for r in rows[1:]])
    err = np.hypot(*(est - true).T)
    assert 0.0 < err.mean() < 0.5  # the controller saw the autopilot's (noisy) EKF state


def test_mavlink_run_completes_over_a_lossy_slow_link(scenario, tmp_path):
    s = _run(scenario, tmp_path, LinkFaults(loss=0.10, latency_s=0.2, seed=5))
    assert s["reached_goal"] and not s["collision"] and s["min_clearance_m"] > 3.0, s
    assert json.loads((tmp_path / "summary.json").read_text()) == s


def test_mavlink_sim_is_registered_by_the_cli():
    from bridge.main import build_parser

    build_parser()
    assert "mavlink-sim" in PLANTS


@pytest.mark.slow
def test_default_scenario_over_mavlink_keeps_the_direct_runs_clearance(tmp_path):
    from scenarios.scenario_file import load_scenario

    scenario = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "pohang.toml")
    direct = run_scenario(scenario, tmp_path / "direct", plots=False).summary
    s = _run(scenario, tmp_path / "mavlink")
    assert s["reached_goal"] and not s["collision"], s
    assert abs(s["min_clearance_m"] - direct["min_clearance_m"]) <= 0.5, (s, direct)
