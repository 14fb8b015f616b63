"""Known walls hand on the vessels a LiDAR tracker would (issue 34): in range and in sight,
never through the land at a side canal's corner, and for the tracker's coasting time after
one goes out of sight."""

from pathlib import Path

import numpy as np

from controller.perception.tracking import TrackerConfig
from scenarios.scenario_file import load_scenario
from scenarios.sensors.perception import KnownWalls

ROOT = Path(__file__).resolve().parents[2]


def crossroads():
    """vessel_crossing's crossroads: the side canal at x 140-156, the launch in it heading
    south at 1.5 m/s from y = 55 at t = 35 s."""
    return load_scenario(ROOT / "scenarios" / "vessel_crossing.toml").world


def launch_y(t):
    return 55.0 - 1.5 * (t - 35.0)


def test_a_vessel_behind_the_corner_is_not_handed_on():
    world = crossroads()
    walls = KnownWalls(world, 50.0, 2.5)
    boat = np.array([110.0, 0.0, 0.0, 2.0, 0.0, 0.0])
    t = 45.0  # the launch 40 m up the side canal, 35-45 m from the boat, the quay between
    assert abs(launch_y(t) - 40.0) < 1e-9
    assert walls.vessel_tracks(t, boat) == ()
    # From the side canal's mouth it is in plain sight.
    assert len(walls.vessel_tracks(t, np.array([148.0, 0.0, 0.0, 2.0, 0.0, 0.0]))) == 1


def test_a_vessel_out_of_sight_is_kept_for_the_trackers_coasting_time():
    world = crossroads()
    walls = KnownWalls(world, 50.0, 2.5)
    t = 45.0
    assert len(walls.vessel_tracks(t, np.array([148.0, 0.0, 0.0, 0, 0, 0]))) == 1
    hidden = np.array([110.0, 0.0, 0.0, 0, 0, 0])  # behind the corner again
    coast = TrackerConfig.max_coast_s
    assert len(walls.vessel_tracks(t + 0.5 * coast, hidden)) == 1
    assert walls.vessel_tracks(t + coast + 0.2, hidden) == ()
