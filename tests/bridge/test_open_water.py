"""Where `canalnav maneuvers --connect` may take the boat (bridge/onboard/open_water.py): the
water with a margin off its walls and open ends, the heading with the most of it (from the
water's edge too), and how far each identification run goes."""

import math
import time

import numpy as np
import pytest

from bridge.onboard.open_water import OpenWater, coast_distance_m, run_length_m
from controller.identification.maneuvers import PAPER_RUNS, SurgeRun
from controller.params import IDENTIFIED
from scenarios.scenario_file import parse_scenario

LAKE = """
[scenario]
name = "lake"
duration_s = 3000

[canal]
centre_line = [[0, 0], [2000, 0]]
width_m = 600

[route]
waypoints = [[0, 0], [2000, 0]]
"""


@pytest.fixture(scope="module")
def lake():
    return parse_scenario(LAKE, "lake.toml")


def test_the_open_end_of_the_canal_is_an_edge_too(lake):
    """The boat starting at the canal's first waypoint sits on its open end: no wall there,
    yet no room for a run either (an EKF's position puts it beyond)."""
    water = OpenWater(lake.world, (0.0, 0.0))
    assert not water.ok([[0.2, 0.0], [-0.3, 0.0], [10.0, 298.0]]).any()
    assert water.ok([[10.0, 0.0], [1000.0, 250.0]]).all()
    assert "water's edge" in water.why_not((0.2, 0.0))
    assert water.why_not((-0.3, 0.0)) == "outside the canal"
    assert "from a wall" in water.why_not((10.0, 298.0))
    assert water.why_not((10.0, 0.0)) == ""


def test_from_the_edge_the_best_heading_leads_into_the_water(lake):
    water = OpenWater(lake.world, (0.0, 0.0))
    for psi in (0.0, math.pi, 2.0):  # whichever way the boat faces at the end of the canal
        ray = water.best_heading((-0.2, 0.0), psi)
        assert abs(ray.heading) < math.radians(11) and ray.entry_m <= 10.0, (psi, ray)
        assert ray.free_m > 1900
    # in the middle facing a bank 200 m off: along the canal, the smaller turn
    ray = water.best_heading((1000.0, 100.0), math.pi / 2)
    assert ray.entry_m == 0.0 and ray.free_m >= 990.0
    assert abs(abs(ray.heading) - math.pi / 2) > math.radians(60)


def test_the_radius_bounds_the_water(lake):
    water = OpenWater(lake.world, (1000.0, 0.0), radius_m=100.0)
    ray = water.best_heading((1000.0, 0.0), 0.0)
    assert 90.0 <= ray.free_m <= 100.0
    assert "radius" in water.why_not((1150.0, 0.0))


def test_a_look_round_takes_milliseconds_not_seconds(lake):
    """Two walls of a thousand legs each: simplified first (this took 5 s of CPU, which a
    10 Hz loop spent as a gap before every run)."""
    water = OpenWater(lake.world, (0.0, 0.0))
    t = time.process_time()
    water.best_heading((500.0, 0.0), 0.0)
    assert time.process_time() - t < 1.0
    assert sum(len(w.points) for w in water.world.walls) <= 8


def test_run_lengths_from_the_model():
    acc, dec, zig, _ = (run_length_m(r, IDENTIFIED, 60.0) for r in PAPER_RUNS)
    assert 450 < acc < 650  # five levels of 60 s from rest, 1.3 to 2.3 m/s, and coasting
    assert 250 < dec < 450
    short = run_length_m(SurgeRun("a", "acceleration", (31.0, 50.6)), IDENTIFIED, 20.0)
    assert short < 0.5 * acc
    assert zig > 60.0 * 1.7  # the straight minute before the zigzag counts


def test_coasting_distance():
    assert coast_distance_m(IDENTIFIED, 0.1) == 0.0
    assert coast_distance_m(IDENTIFIED, 2.0) > coast_distance_m(IDENTIFIED, 1.0) > 0
    assert np.isfinite(coast_distance_m(IDENTIFIED, 2.25))
