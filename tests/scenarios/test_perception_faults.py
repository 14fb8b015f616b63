"""What perception delivers never ends a run (issue 16): degenerate, non-finite, duplicated,
absurd and missing detections are cleaned, counted and logged, and the NMPC drives on."""

import csv
import math

import numpy as np
import pytest

from controller.errors import InputError
from controller.nmpc import NmpcConfig
from controller.nmpc import NmpcController as Core
from controller.params import IDENTIFIED
from scenarios.loop.closed_loop import LoopConfig, run_closed_loop
from scenarios.plants.plant import ModelPlant
from scenarios.scenario_file import parse_scenario
from scenarios.loop.controllers import NmpcController
from scenarios.sensors.perception import KnownWalls

SCENARIO = """
[scenario]
name = "faults"
duration_s = 90
[canal]
centre_line = [[0, 0], [200, 0]]
width_m = 18
[route]
waypoints = [[0, 0], [150, 0]]
[initial]
x_m = 0.0
y_m = 0.0
psi_deg = 0.0
u_mps = 2.0
[sensors]
perception = "known-walls"
[controller]
type = "nmpc"
d_p_m = 2.0
"""


class FaultyPerception:
    """Known walls with a sensor's bad days mixed in, on a fixed schedule (every 7th period
    a zero-length row, every 11th a NaN row, every 13th a duplicate, every 17th a segment
    1 km long, every 19th one far out of range, every 23rd an (M, 5) array, every 29th no
    scan at all)."""

    def __init__(self, world):
        self.walls = KnownWalls(world, 50.0)
        self.k = 0
        self.injected = dict(degenerate=0, non_finite=0, duplicate=0, too_long=0,
                             out_of_range=0, malformed=0, missing=0)

    def segments(self, t, true_state, est_state):
        self.k += 1
        k = self.k
        segs = self.walls.segments(t, true_state, est_state)
        x, y = true_state[:2]
        if k % 29 == 0:
            self.injected["missing"] += 1
            return None
        if k % 23 == 0:
            self.injected["malformed"] += 1
            return np.zeros((3, 5))
        extra = []
        if k % 7 == 0:
            extra.append([x + 20, y, 0.3, 0.0])
            self.injected["degenerate"] += 1
        if k % 11 == 0:
            extra.append([np.nan, y, 0.0, 5.0])
            self.injected["non_finite"] += 1
        if k % 13 == 0 and len(segs):
            extra.append(segs[0])
            self.injected["duplicate"] += 1
        if k % 17 == 0:
            extra.append([x, y + 30.0, 0.0, 1000.0])
            self.injected["too_long"] += 1
        if k % 19 == 0:
            extra.append([x + 5000.0, y, 0.0, 10.0])
            self.injected["out_of_range"] += 1
        return np.vstack([segs, extra]) if extra else segs


def test_the_nmpc_drives_on_through_what_a_faulty_perception_delivers(tmp_path):
    scenario = parse_scenario(SCENARIO)
    from scenarios.loop.runner import loop_config

    perception = FaultyPerception(scenario.world)
    result = run_closed_loop(ModelPlant(IDENTIFIED), NmpcController(scenario), perception,
                             scenario.initial_state, loop_config(scenario, 0), tmp_path,
                             scenario_name="faults")
    s = result.summary
    assert s["reached_goal"] and not s["collision"] and s["fallback_steps"] == 0
    for reason in ("degenerate", "non_finite", "duplicate", "too_long", "out_of_range",
                   "malformed"):
        assert s["segments_cleaned"][reason] == perception.injected[reason] > 0, reason
    assert s["missing_scans"] == perception.injected["missing"] + perception.injected["malformed"]
    assert s["time_blind_s"] == 0.0  # one missing scan at a time is bridged, never blind
    rows = list(csv.DictReader(open(tmp_path / "log.csv")))
    assert sum(int(r["segments_cleaned"]) for r in rows) == sum(
        v for k, v in perception.injected.items() if k != "missing")
    assert {r["blind"] for r in rows} == {"0"}


def test_by_hand_the_nmpc_still_refuses_a_segment_of_no_length():
    ctl = Core(NmpcConfig())
    with pytest.raises(InputError, match="zero or negative length"):
        ctl.step([0, 0, 0, 2, 0, 0], [47, 0], [[20, 0, 0.3, 0.0]], [[0, 0], [100, 0]], 2.0)


def test_a_lidar_outage_longer_than_the_scan_age_makes_the_boat_stop_and_wait(tmp_path):
    text = SCENARIO.replace('perception = "known-walls"',
                            'perception = "known-walls"\n[sensors.lidar]\noutages_s = [[20, 70]]\n'
                            'max_scan_age_s = 0.5')
    scenario = parse_scenario(text.replace("duration_s = 90", "duration_s = 150"))
    from scenarios.loop.runner import loop_config

    events = []
    result = run_closed_loop(ModelPlant(IDENTIFIED), NmpcController(scenario),
                             KnownWalls(scenario.world, 50.0), scenario.initial_state,
                             loop_config(scenario, 0), tmp_path, scenario_name="outage",
                             events=lambda t, text: events.append((t, text)))
    s = result.summary
    assert s["reached_goal"] and s["fallback_steps"] == 0
    assert s["time_blind_s"] == pytest.approx(49.5, abs=0.15)  # 20.5 .. 70 s
    assert s["time_held_s"] > 5.0 and s["max_speed_while_held_mps"] < 0.1
    assert events[0][1].startswith("waiting: blind") and events[0][0] == pytest.approx(20.5)
    assert events[1][1] == "the way is clear: going on" and events[1][0] >= 70.0
    rows = list(csv.DictReader(open(tmp_path / "log.csv")))
    blind = [r for r in rows if r["blind"] == "1"]
    assert blind[0]["status"].startswith("waiting: blind")
    assert float(blind[-1]["perception_age_s"]) == pytest.approx(49.9, abs=0.15)
