"""Tracks that mean boats (issue 34), in closed loop with the LiDAR: no confirmed track on a
quay wall for more than 1 s, and at most one track id switch per vessel: the bar on every
vessel scenario file (vessel_crossing's launch track was once drawn onto the quay corner it
passes, 2.1 s, with two ids) and the workboat encounter (a 1.5 s track on the side canal's
wall seen end-on while the boat waits at the crossing: at that glancing angle the wall's
returns are farther apart than the bearing bins, and the water "seen" beyond its last
return lay in an empty bin; the hull evidence now asks the bins either side); not yet met: the crowded
encounters (vessels and moored boats a few metres apart make one cluster, whose tracks trade
ids; in fuzz seed 1's first 200 cases, 31 of 285 vessels changed track id more than once)."""

from dataclasses import replace
from pathlib import Path

import pytest

from scenarios.loop.runner import run_scenario
from scenarios.scenario_file import load_scenario

ROOT = Path(__file__).resolve().parents[2]
FILES = [ROOT / "scenarios" / f"vessel_{n}.toml"
         for n in ("meeting", "kayak", "overtaking", "following", "crossing")] + [
    Path(__file__).parent / "encounters" / "workboat_from_port.toml"]


@pytest.mark.slow
@pytest.mark.parametrize("path", FILES, ids=[f.stem for f in FILES])
def test_no_wall_track_over_a_second_and_one_id_per_vessel(path, tmp_path):
    scenario = replace(load_scenario(path), perception="lidar")
    tracking = run_scenario(scenario, tmp_path, plots=False).summary["tracking"]
    assert tracking["longest_wall_track_s"] <= 1.0, tracking
    assert max(tracking["id_switches"].values()) <= 1, tracking
