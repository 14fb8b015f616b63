"""Other vessels in scenario files: their motion on simulation time, their hulls, and clear
errors for a vessel that cannot be (issue 17)."""

import math

import numpy as np
import pytest

from controller.errors import InputError
from scenarios.scenario_file import parse_scenario
from scenarios.world.vessels import Hull, Vessel

BASE = """
[scenario]
name = "vessels"
duration_s = 100
[canal]
centre_line = [[0, 0], [300, 0]]
width_m = 20
[[obstacle]]
name = "pier"
outline = [[100, 6], [110, 6], [110, 10], [100, 10]]
z_top_m = 1.5
[route]
waypoints = [[0, 0], [290, 0]]
[[vessel]]
name = "tour boat"
[vessel.hull]
length_m = 12
beam_m = 3.5
[vessel.route]
waypoints = [[250, -3], [50, -3]]
speed_mps = 1.5
start_s = 10
waits = [[1, 5]]
"""


def test_a_route_vessel_waits_for_its_start_then_runs_at_its_speed():
    s = parse_scenario(BASE)
    v = s.world.vessels[0]
    assert np.allclose(v.pose_at(0.0)[:2], (250, -3)) and np.allclose(v.pose_at(10.0)[:2], (250, -3))
    assert np.allclose(v.pose_at(30.0)[:2], (220, -3), atol=1e-6)
    assert v.pose_at(30.0)[2] == pytest.approx(math.pi)
    assert np.allclose(v.velocity_at(30.0), (-1.5, 0.0), atol=1e-6)
    assert np.allclose(v.pose_at(99.0)[:2], (250 - 1.5 * 89, -3), atol=1e-6)
    outline = v.outline_at(30.0)
    assert outline.shape == (5, 2)  # pointed: bow, two shoulders, two stern corners
    assert outline[:, 0].min() == pytest.approx(214.0) and outline[:, 0].max() == pytest.approx(226.0)


def test_waits_and_the_end_of_the_route_hold_the_vessel():
    hull = Hull(10.0, 3.0)
    v = Vessel.on_route("v", hull, [[0, 0], [10, 0], [20, 0]], 1.0, 60.0, waits=[(1, 5.0)])
    assert np.allclose(v.pose_at(12.0)[:2], (10, 0)) and np.allclose(v.pose_at(17.0)[:2], (12, 0))
    assert np.allclose(v.pose_at(50.0)[:2], (20, 0)) and np.allclose(v.velocity_at(50.0), 0)


def test_a_wandering_course_is_seeded_and_stops_after_its_distance():
    hull = Hull(3.5, 0.8, 0.6, "rectangle")
    a = Vessel.on_course("k", hull, (0, 0), math.radians(90), 0.5, 80.0, 5.0, 12.0, seed=3,
                         distance_m=10.0)
    b = Vessel.on_course("k", hull, (0, 0), math.radians(90), 0.5, 80.0, 5.0, 12.0, seed=3,
                         distance_m=10.0)
    c = Vessel.on_course("k", hull, (0, 0), math.radians(90), 0.5, 80.0, 5.0, 12.0, seed=4,
                         distance_m=10.0)
    assert np.array_equal(a.poses, b.poses) and not np.array_equal(a.poses, c.poses)
    travelled = np.hypot(*np.diff(a.poses[:, :2], axis=0).T).sum()
    assert travelled == pytest.approx(10.0, abs=0.06)
    assert np.allclose(a.pose_at(2.0)[:2], (0, 0))


def test_a_course_pauses_at_its_waits_then_goes_on_to_its_distance():
    hull = Hull(3.5, 0.8, 0.6, "rectangle")
    v = Vessel.on_course("k", hull, (0, 0), 0.0, 0.5, 80.0, 5.0, distance_m=10.0,
                         waits=[(4.0, 20.0)])
    assert np.allclose(v.pose_at(13.0)[:2], (4, 0), atol=0.06)  # arrived 8 s after the start
    assert np.allclose(v.pose_at(25.0)[:2], (4, 0), atol=0.06)  # resting for 20 s
    assert np.allclose(v.velocity_at(25.0), 0)
    assert np.allclose(v.pose_at(35.0)[:2], (5, 0), atol=0.06)  # on again at 33 s
    assert np.allclose(v.pose_at(70.0)[:2], (10, 0), atol=0.06)  # and stopped after 10 m
    plain = Vessel.on_course("k", hull, (0, 0), 0.0, 0.5, 80.0, 5.0, distance_m=10.0)
    assert np.allclose(plain.pose_at(25.0)[:2], (10, 0), atol=0.06)


def test_a_course_wait_is_checked_in_the_file():
    course = BASE.split("[vessel.route]")[0] + (
        "\n[vessel.course]\nx_m = 10\ny_m = 0\ncourse_deg = 0\nspeed_mps = 1\n"
        "distance_m = 20\n")
    s = parse_scenario(course + "waits = [[5, 10]]\n")
    assert np.allclose(s.world.vessels[0].pose_at(12.0)[:2], (15, 0), atol=0.06)
    bad(course + "waits = [[5]]\n", "field 'vessel[0].course.waits'", "pairs")
    bad(course + "waits = [[-1, 3]]\n", "field 'vessel[0].course.waits'")
    bad(course.replace("speed_mps = 1", "speed_mps = 0") + "waits = [[5, 10]]\n",
        "field 'vessel[0].course.waits'", "never reaches")


def test_the_lidar_renders_the_vessels_where_they_are_at_each_scan():
    from scenarios.sensors.perception import LidarPerception

    s = parse_scenario(BASE)
    p = LidarPerception(s.world, seed=1)
    state = np.array([200.0, 2.0, math.pi, 0, 0, 0])  # facing the vessel, 5 m beside its track
    near = p.simulator.scan_labelled(state[:3], 0.0, time_s=30.0,
                                     extra_obstacles=s.world.vessel_obstacles(30.0))
    from scenarios.sensors.lidar import OBSTACLE

    hits = near.points[near.labels == OBSTACLE]
    c, sn = math.cos(state[2]), math.sin(state[2])
    xy = np.column_stack([state[0] + c * hits[:, 0] - sn * hits[:, 1],
                          state[1] + sn * hits[:, 0] + c * hits[:, 1]])
    xy = xy[xy[:, 0] > 150.0]  # (the pier is an obstacle too, at 100-110 m)
    assert len(xy) > 50
    assert xy[:, 0].min() > 213.5 and xy[:, 0].max() < 226.5  # on the hull at t = 30 s


def bad(text, *words):
    with pytest.raises(InputError) as info:
        parse_scenario(text, "v.toml")
    for w in words:
        assert w in str(info.value), str(info.value)


@pytest.mark.parametrize("old, new, words", [
    ("waypoints = [[250, -3], [50, -3]]", "waypoints = [[250, -3]]",
     ["field 'vessel[0].route.waypoints'", "at least 2"]),
    ("speed_mps = 1.5", "speed_mps = -1", ["field 'vessel[0].route.speed_mps'", ">= 0"]),
    ("length_m = 12", "length_m = 0", ["field 'vessel[0].hull.length_m'", "> 0"]),
    ("beam_m = 3.5", "beam_m = -2", ["field 'vessel[0].hull.beam_m'"]),
    ("waypoints = [[250, -3], [50, -3]]", "waypoints = [[250, -30], [50, -3]]",
     ["field 'vessel[0].route.waypoints'", "starts off the water"]),
    ("waypoints = [[250, -3], [50, -3]]", "waypoints = [[250, -3], [150, -3], [120, 40]]",
     ["field 'vessel[0].route.waypoints'", "crosses a wall"]),
    ("waypoints = [[250, -3], [50, -3]]", "waypoints = [[105, 8], [50, 5]]",
     ["field 'vessel[0].route.waypoints'", "inside obstacle 'pier'"]),
    ("waits = [[1, 5]]", "waits = [[7, 5]]", ["field 'vessel[0].route.waits'"]),
    ("[vessel.route]", "[vessel.course]", ["field 'vessel[0].course.x_m'", "is required"]),
])
def test_a_vessel_that_cannot_be_is_a_clear_error_naming_the_field(old, new, words):
    bad(BASE.replace(old, new), *words)


def test_a_vessel_needs_one_motion():
    no_motion = BASE.split("[vessel.route]")[0]
    bad(no_motion, "field 'vessel[0].route'", "one of the two")
    course = "\n[vessel.course]\nx_m = 10\ny_m = 0\ncourse_deg = 0\nspeed_mps = 1\n"
    bad(BASE + course, "field 'vessel[0].route'", "one of the two")
    bad(no_motion + course.replace("speed_mps = 1", "speed_mps = 1\ndistance_m = 0"),
        "field 'vessel[0].course.distance_m'")


def test_two_vessels_may_not_start_in_one_place():
    second = BASE[BASE.index("[[vessel]]"):].replace('name = "tour boat"', 'name = "twin"')
    bad(BASE + second, "field 'vessel[1].route.waypoints'", "starts inside 'tour boat'")


def test_a_vessels_prism_is_its_hull_placed_and_the_same_as_one_checked_anew():
    from scenarios.world.canal import Obstacle

    v = Vessel.on_route("launch", Hull(8.0, 2.5, 1.4), [[0.0, 0.0], [40.0, 30.0]], 1.5, 60.0)
    for t in (0.0, 7.3, 7.3, 30.0):
        prism = v.obstacle_at(t)
        fresh = Obstacle(v.outline_at(t), z_top_m=1.4, kind="boat", name="launch")
        np.testing.assert_array_equal(prism.outline, fresh.outline)
        assert (prism.z_top_m, prism.kind, prism.name) == (1.4, "boat", "launch")
        assert not prism.outline.flags.writeable
    assert v.obstacle_at(7.3) is v.obstacle_at(7.3)  # made once for the instant
    pose = v.pose_at(7.3)
    pose[0] += 100.0  # a caller's copy: the vessel is not moved
    assert v.pose_at(7.3)[0] != pose[0]
    with pytest.raises(ValueError):
        v.obstacle_at(0.0).moved(np.zeros((3, 2)))
