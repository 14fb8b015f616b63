"""The NMPC with the water current estimated, ignored (still water) and told (issue 18), in
closed loop on the Python model: the estimate removes the steady offset still water leaves."""

import csv

import numpy as np
import pytest

from scenarios.loop.runner import run_scenario, with_water
from scenarios.scenario_file import parse_scenario

SCENARIO = """
[scenario]
name = "crossing"
duration_s = 110
seed = 3
[canal]
centre_line = [[0, 0], [200, 0]]
width_m = 16
[route]
waypoints = [[0, 0], [200, 0]]
[initial]
x_m = 0.0
y_m = 0.0
psi_deg = 0.0
u_mps = 2.0
[current]
north_mps = 0.0
east_mps = 0.4
[sensors]
perception = "known-walls"
[controller]
type = "nmpc"
d_p_m = 2.0
"""


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = parse_scenario(SCENARIO)
    out = {}
    for mode in ("estimated", "still", "true"):
        d = tmp_path_factory.mktemp(mode)
        out[mode] = (run_scenario(with_water(base, mode), d, plant="python-model",
                                  plots=False).summary, d)
    return out


def test_the_estimate_removes_the_offset_that_still_water_leaves(runs):
    est, still, true = (runs[m][0] for m in ("estimated", "still", "true"))
    assert all(s["reached_goal"] and not s["collision"] for s in (est, still, true))
    assert est["mean_cross_track_m"] < 0.5 * still["mean_cross_track_m"]
    assert est["mean_cross_track_m"] < true["mean_cross_track_m"] + 0.1
    assert est["min_clearance_m"] > still["min_clearance_m"]
    assert est["water"]["mode"] == "estimated" and still["water"]["mode"] == "still"
    assert est["water"]["within_after_steady_s"] <= 30.0
    assert est["water"]["mean_error_after_mps"] < 0.05


def test_the_estimate_its_spread_and_the_truth_are_logged_every_step(runs):
    summary, d = runs["estimated"]
    rows = list(csv.DictReader(open(d / "log.csv")))
    assert len(rows) == summary["steps"]
    last = rows[-1]
    assert float(last["current_true_e_mps"]) == 0.4
    assert abs(float(last["current_est_e_mps"]) - 0.4) < 0.05
    assert 0 < float(last["current_sigma_e_mps"]) < 0.1
    assert all(np.isfinite(float(last[k])) for k in ("bias_u_mps2", "bias_v_mps2", "bias_r_radps2"))


def test_an_unknown_water_mode_is_a_clear_error():
    from controller.errors import InputError

    with pytest.raises(InputError, match="water 'wet'"):
        with_water(parse_scenario(SCENARIO), "wet")
