"""Scenario files: loading, and clear errors that name the file and the field."""

import math

import numpy as np
import pytest

from controller.errors import InputError
from controller.params import IDENTIFIED
from scenarios.scenario_file import load_scenario, parse_scenario, round_corners

BASE = """
[scenario]
name = "sbend"
duration_s = 300

[canal]
centre_line = [[0, 0], [150, 0], [250, 100], [400, 100]]
corner_radius_m = 40
width_profile = [[0, 20], [150, 20], [180, 12], [400, 12]]

[[obstacle]]
name = "moored boat"
kind = "boat"
outline = [[50, 7], [58, 7], [58, 9.5], [50, 9.5]]
z_top_m = 1.2

[route]
spacing_m = 20
[[route.offsets]]
from_s_m = 60
to_s_m = 100
offset_m = 5

[plant.boat]
m11 = 2000.0

[controller]
type = "nmpc"
d_p_m = 2
"""


def load(text, tmp_path, name="s.toml"):
    path = tmp_path / name
    path.write_text(text)
    return load_scenario(path), path


def test_loads_a_canal_with_bends_width_profile_obstacle_and_offset_route(tmp_path):
    s, _ = load(BASE, tmp_path)
    assert s.name == "sbend" and s.duration_s == 300 and s.controller == "nmpc"
    assert s.world.length_m == pytest.approx(438.0, abs=1.0)  # corners cut by the arcs
    assert len(s.world.walls) == 2 and len(s.world.obstacles) == 1
    # the route is offset 5 m to starboard between s = 60 and 100 m
    assert s.waypoints[3] == pytest.approx([60.0, 5.0])
    assert s.waypoints[1] == pytest.approx([20.0, 0.0])
    # the plant differs from the controller's model only where the file says so
    assert s.plant_params.m11 == 2000.0 and s.controller_params == IDENTIFIED
    assert s.initial_state == pytest.approx([0, 0, 0, 0, 0, 0])
    # width 20 m at the start: walls 10 m either side of the centre line
    assert s.world.clearance(np.array([[10.0, 0.0]]))[0] == pytest.approx(10.0)


def test_round_corners_gives_arcs_of_the_radius():
    c = round_corners(np.array([[0, 0], [150, 0], [250, 100], [400, 100]], float), 40.0, 2.0)
    d = np.diff(c, axis=0)
    turn = np.abs(np.diff(np.unwrap(np.arctan2(d[:, 1], d[:, 0]))))
    assert turn.max() == pytest.approx(2.0 / 40.0, rel=0.05)  # 2 m steps on a 40 m radius
    assert np.hypot(*d.T).max() < 2.01


@pytest.mark.parametrize("change, words", [
    (("duration_s = 300", "duration_s = -5"), ["'scenario.duration_s'", "must be > 0", "-5"]),
    (("corner_radius_m = 40", "corner_radius_m = 40\nwidht_m = 3"), ["'canal.widht_m'", "unknown field"]),
    (("offset_m = 5", "offset_m = 15"), ["'route.waypoints'", "waypoint 3", "outside the canal"]),
    (("[[obstacle]]", "[[obstacle]]\nheight = 3"), ["'obstacle[0].height'", "unknown field"]),
    (('type = "nmpc"', 'type = "mpc"'), ["'controller.type'", "'mpc'"]),
    (("m11 = 2000.0", "m11 = -1.0"), ["[plant.boat]", "'m11'", "positive"]),
    (("[scenario]", "[senario]"), ["'scenario'", "is required"]),
    (("duration_s = 300", 'duration_s = "long"'), ["'scenario.duration_s'", "expected a number"]),
])
def test_bad_scenarios_name_file_and_field(tmp_path, change, words):
    with pytest.raises(InputError) as err:
        load(BASE.replace(*change), tmp_path, "bad.toml")
    msg = str(err.value)
    assert msg.startswith(str(tmp_path / "bad.toml"))
    for w in words:
        assert w in msg, msg


def test_self_intersecting_wall_is_named(tmp_path):
    text = BASE.replace(
        """centre_line = [[0, 0], [150, 0], [250, 100], [400, 100]]
corner_radius_m = 40
width_profile = [[0, 20], [150, 20], [180, 12], [400, 12]]""",
        """centre_line = [[0, 0], [400, 0]]
[[canal.wall]]
name = "west quay"
points = [[0, -10], [100, -10], [100, 10], [50, -20]]
[[canal.wall]]
points = [[0, 10], [400, 10]]""")
    with pytest.raises(InputError) as err:
        load(text, tmp_path, "bad.toml")
    msg = str(err.value)
    assert "bad.toml" in msg and "'west quay'" in msg and "crosses itself" in msg


def test_waypoint_inside_an_obstacle_is_named(tmp_path):
    text = BASE.replace("offset_m = 5", "offset_m = 8").replace("[50, 7], [58, 7], [58, 9.5], [50, 9.5]",
                                                               "[55, 7], [65, 7], [65, 9.5], [55, 9.5]")
    with pytest.raises(InputError, match="inside obstacle 'moored boat'"):
        load(text, tmp_path)


def test_invalid_toml_and_missing_file(tmp_path):
    with pytest.raises(InputError, match="not valid TOML"):
        parse_scenario("[scenario\n", "x.toml")
    with pytest.raises(InputError, match="no such scenario file"):
        load_scenario(tmp_path / "none.toml")


def test_initial_state_in_degrees_at_the_edge(tmp_path):
    s, _ = load(BASE + "\n[initial]\nx_m = 5.0\ny_m = 1.0\npsi_deg = 90.0\nu_mps = 1.5\n", tmp_path)
    assert s.initial_state == pytest.approx([5.0, 1.0, math.pi / 2, 1.5, 0, 0])
