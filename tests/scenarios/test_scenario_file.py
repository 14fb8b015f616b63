"""Scenario files: loading, and clear errors that name the file and the field."""

import math

import numpy as np
import pytest

from controller.errors import InputError
from controller.params import IDENTIFIED
from scenarios.sensors.lidar import LidarNoise
from scenarios.scenario_file import load_scenario, parse_scenario, round_corners
from scenarios.sensors.gps_ahrs import AhrsConfig, GpsConfig

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
    (("offset_m = 5", "offset_m = 15"),
     ["'route.offsets[0].offset_m'", "waypoint 3 (60.0, 15.0)", "lies outside the canal"]),
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
    assert msg.startswith(str(tmp_path / "bad.toml"))
    assert "field 'canal.wall[0].points'" in msg and "'west quay'" in msg and "crosses itself" in msg


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


# -- on the water ----------------------------------------------------------------------------
STRAIGHT = """
[scenario]
duration_s = 100

[canal]
centre_line = [[0, 0], [100, 0]]
width_m = 16

[route]
waypoints = [[0, 0], [100, 0]]
"""


def with_waypoints(text, waypoints):
    return text.replace("waypoints = [[0, 0], [100, 0]]", f"waypoints = {waypoints}")


def bad(text, tmp_path, *words):
    """Loading `text` fails with an error that starts with the file and holds every word."""
    with pytest.raises(InputError) as err:
        load(text, tmp_path, "bad.toml")
    msg = str(err.value)
    assert msg.startswith(str(tmp_path / "bad.toml") + ": "), msg
    for w in words:
        assert w in msg, msg
    return msg


@pytest.mark.parametrize("waypoints, words", [
    # through a wall vertex (walls are resampled every 2 m): not a proper crossing, still outside
    ("[[0, 0], [50, 20], [100, 0]]", ["waypoint 1 (50.0, 20.0) lies outside the canal"]),
    ("[[0, 0], [300, 0]]", ["waypoint 1 (300.0, 0.0) lies outside the canal"]),  # past the end
    ("[[-50, 0], [100, 0]]", ["waypoint 0 (-50.0, 0.0) lies outside the canal"]),
    ("[[0, 0], [50, 8], [100, 0]]", ["waypoint 1 (50.0, 8.0) lies on wall 'right'"]),
])
def test_waypoints_off_the_water_are_named(tmp_path, waypoints, words):
    bad(with_waypoints(STRAIGHT, waypoints), tmp_path, "field 'route.waypoints'", *words)


def test_waypoints_at_the_open_ends_and_near_the_walls_are_fine(tmp_path):
    s, _ = load(with_waypoints(STRAIGHT, "[[0, 7.5], [50, -7.9], [100, 0]]"), tmp_path)
    assert s.waypoints[1] == pytest.approx([50.0, -7.9])


def test_the_start_off_the_water_names_the_initial_fields(tmp_path):
    msg = bad(STRAIGHT + "[initial]\nx_m = 20\ny_m = 9\npsi_deg = 0\n", tmp_path,
              "fields 'initial.x_m', 'initial.y_m': the start (20.0, 9.0) lies outside the canal")
    assert "waypoint" not in msg


EXPLICIT = """
[scenario]
duration_s = 100

[canal]
[[canal.wall]]
name = "west quay"
points = [[0, -8], [50, -8], [100, -8]]
[[canal.wall]]
name = "east quay"
points = [[100, 8], [50, 8], [0, 8]]

[route]
waypoints = [[0, 0], [100, 0]]
"""

THREE_WALLS = EXPLICIT.replace('''name = "east quay"
points = [[100, 8], [50, 8], [0, 8]]''', '''name = "east quay north"
points = [[100, 8], [50, 8]]
[[canal.wall]]
name = "east quay south"
points = [[50, 8], [0, 8]]''').replace("[canal]\n", "[canal]\ncentre_line = [[0, 0], [100, 0]]\n")


def test_explicit_walls_are_closed_at_their_ends(tmp_path):
    s, _ = load(EXPLICIT, tmp_path)
    assert s.world.centre_line is None and len(s.world.water_ring) == 6
    bad(with_waypoints(EXPLICIT, "[[0, 0], [50, 20], [100, 0]]"), tmp_path,
        "field 'route.waypoints': waypoint 1 (50.0, 20.0) lies outside the canal")
    bad(with_waypoints(EXPLICIT, "[[0, 0], [250, 0]]"), tmp_path,
        "waypoint 1 (250.0, 0.0) lies outside the canal")


def test_more_than_two_walls_are_checked_from_the_centre_line_counting_touches(tmp_path):
    s, _ = load(THREE_WALLS, tmp_path)
    assert s.world.water_ring is None
    # through (50, 8), where the two east pieces meet
    bad(with_waypoints(THREE_WALLS, "[[0, 0], [50, 20], [100, 0]]"), tmp_path,
        "waypoint 1 (50.0, 20.0) lies outside the canal")
    bad(with_waypoints(THREE_WALLS, "[[0, 0], [300, 0]]"), tmp_path,
        "waypoint 1 (300.0, 0.0) lies outside the canal")


# -- walls that cross or fold ------------------------------------------------------------------
def test_two_walls_that_cross_name_both_fields(tmp_path):
    bad(EXPLICIT.replace("[[0, -8], [50, -8], [100, -8]]", "[[0, -8], [50, -8], [100, 10]]"),
        tmp_path, "field 'canal.wall[0].points': walls 'west quay' and 'east quay' (canal.wall[1]) "
                  "cross each other (their legs 1 and 0)")


def test_a_bend_tighter_than_half_the_width_names_the_centre_line(tmp_path):
    u_turn = with_waypoints(STRAIGHT, "[[0, 0], [0, 10]]").replace(
        "centre_line = [[0, 0], [100, 0]]",
        "centre_line = [[0, 0], [100, 0], [100, 10], [0, 10]]\ncorner_radius_m = 5")
    bad(u_turn, tmp_path, "field 'canal.centre_line'", "folds back on itself",
        "tighter than half the width (8.0 m)", "corner_radius_m", "width_m / width_profile")


def test_a_repeated_centre_line_point_is_named_not_a_nan(tmp_path):
    text = BASE.replace("[[0, 0], [150, 0], [250, 100], [400, 100]]",
                        "[[0, 0], [150, 0], [150, 0], [250, 100], [400, 100]]")
    bad(text, tmp_path, "field 'canal.centre_line': point 2 (150, 0) repeats the one before it")


# -- files that are not scenario files --------------------------------------------------------
def test_a_file_that_is_not_utf8_or_a_folder_is_named(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(("# caf\xe9\n" + STRAIGHT).encode("latin-1"))
    with pytest.raises(InputError, match=r"latin1.toml: not UTF-8 text \(byte 5"):
        load_scenario(path)
    with pytest.raises(InputError, match="is a folder, not a scenario file"):
        load_scenario(tmp_path)


# -- seeds, snapshots, obstacles, waypoints ----------------------------------------------------
@pytest.mark.parametrize("line, words", [
    ("seed = -3", ["field 'scenario.seed': must be >= 0, got -3"]),
    ("seed = 1.5", ["field 'scenario.seed': expected a whole number, got 1.5"]),
    ("snapshot_times_s = [true, 3]", ["field 'scenario.snapshot_times_s'", "[True, 3]"]),
    ("snapshot_times_s = [-1, 3]", ["field 'scenario.snapshot_times_s': must all be >= 0"]),
])
def test_bad_scenario_table_values(tmp_path, line, words):
    bad(STRAIGHT.replace("duration_s = 100", f"duration_s = 100\n{line}"), tmp_path, *words)


def test_a_zero_area_obstacle_is_an_error(tmp_path):
    bad(BASE.replace("[[50, 7], [58, 7], [58, 9.5], [50, 9.5]]", "[[50, 7], [54, 8], [58, 9]]"),
        tmp_path, "field 'obstacle[0].outline': obstacle 'moored boat': encloses no area")


@pytest.mark.parametrize("waypoints", ["[[0, 0], [0, 0]]", "[[5, 5], [5, 5], [5, 5]]"])
def test_waypoints_need_two_distinct_points(tmp_path, waypoints):
    bad(with_waypoints(STRAIGHT, waypoints), tmp_path,
        "field 'route.waypoints': needs at least two distinct waypoints")


def test_a_repeated_first_waypoint_still_heads_along_the_first_leg(tmp_path):
    s, _ = load(with_waypoints(STRAIGHT, "[[0, 0], [0, 0], [50, 5]]"), tmp_path)
    assert s.initial_state[2] == pytest.approx(math.atan2(5, 50)) and len(s.waypoints) == 3


def test_explicit_and_generated_waypoints_are_not_mixed(tmp_path):
    bad(STRAIGHT + "spacing_m = 10\n", tmp_path, "field 'route.spacing_m'", "not both")


def test_points_must_be_numbers_not_booleans_or_text(tmp_path):
    bad(with_waypoints(STRAIGHT, '[[0, 0], [100, "0"]]'), tmp_path,
        "field 'route.waypoints': expected a list of [north_m, east_m] pairs of numbers")
    bad(with_waypoints(STRAIGHT, "[[0, 0], [100, true]]"), tmp_path, "field 'route.waypoints'")
    bad(STRAIGHT.replace("width_m = 16", "wall_height_m = [1.5, true]\nwidth_m = 16"), tmp_path,
        "field 'canal.wall_height_m': expected a number or a [left, right] pair")


# -- controller options ------------------------------------------------------------------------
@pytest.mark.parametrize("controller, options, words", [
    ("los-pid", "bogus = 1", ["'controller.options.bogus'", "los-pid controller takes no options"]),
    ("lexicographic", "slack_weight = 1.0", ["'controller.options.slack_weight'", "takes no options"]),
    ("nmpc", "bogus = 1", ["'controller.options.bogus'", "unknown NMPC option", "slack_weight"]),
    ("nmpc", "horizon = 2.5", ["'controller.options.horizon'", "expected a whole number, got 2.5"]),
    ("nmpc", "horizon = 0", ["'controller.options.horizon'", "must be a positive integer"]),
    ("nmpc", "slack_weight = true", ["'controller.options.slack_weight'", "expected a number"]),
    ("nmpc", "slack_weight = -1.0", ["'controller.options.slack_weight'", "must not be negative"]),
    ("nmpc", "q_diag = [1, 2]", ["'controller.options.q_diag'", "needs 8 weights"]),
    ("nmpc", 'r_diag = [1, "a"]', ["'controller.options.r_diag'", "expected a list of numbers"]),
    ("nmpc", "hull_offsets_m = [1, -1]", ["'controller.options.hull_offsets_m'", "fixed"]),
    ("nmpc", "hull_radius_m = 2.0", ["'controller.options.hull_radius_m'", "fixed"]),
    ("nmpc", "control_period_s = 0.5", ["'controller.options.control_period_s'", "10 Hz"]),
    ("nmpc", "terminal_factor = -2.0", ["'controller.options.terminal_factor'", "non-negative"]),
    ("nmpc", 'method = "newton"', ["'controller.options.method'", "rti, sqp, ipopt"]),
    ("nmpc", "knows_current = 1", ["'controller.options.knows_current'", "expected true or false"]),
    ("nmpc", "separation_m = 3.0", ["'controller.options.separation_m'", "controller.d_p_m"]),
])
def test_controller_options_are_checked_on_load(tmp_path, controller, options, words):
    text = STRAIGHT + f'[controller]\ntype = "{controller}"\n[controller.options]\n{options}\n'
    bad(text, tmp_path, *words)


@pytest.mark.parametrize("options, limit", [("", "4.69 m/s at 100 %"),
                                            ("[controller.options]\nnT_max = 50\n", "at 50 %")])
def test_a_target_speed_above_the_boats_top_speed_is_an_error(tmp_path, options, limit):
    text = STRAIGHT.replace("[route]\n", "[route]\ntarget_speed_mps = 6.0\n")
    bad(text + '[controller]\ntype = "nmpc"\n' + options, tmp_path,
        "field 'route.target_speed_mps': 6 m/s is above the controller's boat's top speed", limit)


def test_good_nmpc_options_are_kept(tmp_path):
    text = STRAIGHT + ('[controller]\ntype = "nmpc"\n[controller.options]\nmethod = "sqp"\n'
                       "knows_current = true\nslack_weight = 1000\nhorizon = 20\n"
                       "q_diag = [1, 1, 400, 10, 0, 1000, 0, 0]\n")
    s, _ = load(text, tmp_path)
    assert s.controller_options == {"method": "sqp", "knows_current": True, "slack_weight": 1000,
                                    "horizon": 20, "q_diag": [1, 1, 400, 10, 0, 1000, 0, 0]}


# -- sensors and criteria -------------------------------------------------------------------
SENSORS = """
[sensors.gps]
rate_hz = 10
pos_sigma_m = 0.5
vel_sigma_mps = 0.1
[sensors.ahrs]
heading_sigma_deg = 1.0
yaw_rate_sigma_degps = 0.5
accel_sigma_mps2 = 0.05
[sensors.lidar]
range_sigma_m = 0.05
dropout = 0.1
water_speckle = 0.02
water_ripple_m = 0.1
spray_points = 50
spray_length_m = 8.0
spray_height_m = 0.5
"""


def test_sensor_settings_are_read_with_degrees_at_the_edge(tmp_path):
    s, _ = load(STRAIGHT + SENSORS, tmp_path)
    assert s.gps == GpsConfig(rate_hz=10.0, pos_sigma_m=0.5, vel_sigma_mps=0.1)
    assert s.ahrs.heading_sigma_rad == pytest.approx(math.radians(1.0))
    assert s.ahrs.yaw_rate_sigma_radps == pytest.approx(math.radians(0.5))
    assert s.ahrs.accel_sigma_mps2 == 0.05 and s.ahrs.rate_hz == AhrsConfig().rate_hz
    assert s.lidar_noise == LidarNoise(range_sigma_m=0.05, dropout=0.1, water_speckle=0.02,
                                       water_ripple_m=0.1, spray_points=50, spray_length_m=8.0,
                                       spray_height_m=0.5)


def test_sensor_defaults_are_the_sensors_own(tmp_path):
    s, _ = load(STRAIGHT + "[sensors.ahrs]\naccel_sigma_mps2 = 0.1\n", tmp_path)
    assert s.gps == GpsConfig() and s.lidar_noise == LidarNoise()
    assert s.ahrs.heading_sigma_rad == AhrsConfig().heading_sigma_rad  # not round-tripped
    assert s.ahrs.accel_sigma_mps2 == 0.1


@pytest.mark.parametrize("change, words", [
    (("rate_hz = 10", "rate_hz = 0"), ["'sensors.gps.rate_hz'", "must be > 0"]),
    (("rate_hz = 10", "rate_hz = 200"), ["'sensors.gps.rate_hz'", "must be <= 100.0"]),
    (("rate_hz = 10", "rate_hz = 40"), ["'sensors.gps.rate_hz'", "must divide 100 Hz", "got 40"]),
    (("pos_sigma_m = 0.5", "pos_sigma_m = -0.5"), ["'sensors.gps.pos_sigma_m'", "must be >= 0"]),
    (("heading_sigma_deg = 1.0", "heading_sigma_rad = 0.01"),
     ["'sensors.ahrs.heading_sigma_rad'", "unknown field"]),
    (("dropout = 0.1", "dropout = 1.5"), ["'sensors.lidar.dropout'", "must be <= 1"]),
    (("water_speckle = 0.02", "water_speckle = 0.95"),
     ["'sensors.lidar.water_speckle'", "dropout + water_speckle"]),
    (("spray_points = 50", "spray_points = 50.5"), ["'sensors.lidar.spray_points'", "whole number"]),
    (("spray_height_m = 0.5", 'spray_height_m = "low"'),
     ["'sensors.lidar.spray_height_m'", "expected a number"]),
])
def test_bad_sensor_settings_are_named(tmp_path, change, words):
    bad(STRAIGHT + SENSORS.replace(*change), tmp_path, *words)


def test_criteria_for_wide_and_narrow_stretches(tmp_path):
    s, _ = load(STRAIGHT + "[criteria]\nmin_clearance_where_wide_m = 4.3\n"
                "max_mean_centre_offset_narrow_m = 0.5\n", tmp_path)
    assert s.criteria.min_clearance_where_wide_m == 4.3
    assert s.criteria.max_mean_centre_offset_narrow_m == 0.5
    assert load(STRAIGHT, tmp_path)[0].criteria.min_clearance_where_wide_m is None
    bad(STRAIGHT + "[criteria]\nmax_mean_centre_offset_narrow_m = -1\n", tmp_path,
        "'criteria.max_mean_centre_offset_narrow_m'", "must be >= 0")


def test_a_centre_line_turning_straight_back_is_named(tmp_path):
    text = with_waypoints(STRAIGHT, "[[0, 0], [60, 0]]").replace(
        "centre_line = [[0, 0], [100, 0]]", "centre_line = [[0, 0], [100, 0], [50, 0]]\ncorner_radius_m = 10")
    bad(text, tmp_path, "field 'canal.centre_line': turns straight back on itself")


def test_an_obstacle_can_be_removed_at_a_time(tmp_path):
    s, _ = load(BASE.replace("z_top_m = 1.2", "z_top_m = 1.2\nremove_at_s = 40"), tmp_path)
    assert s.world.obstacles[0].remove_at_s == 40.0
    bad(BASE.replace("z_top_m = 1.2", "z_top_m = 1.2\nremove_at_s = -3"), tmp_path,
        "field 'obstacle[0].remove_at_s': must be >= 0")
    bad(BASE.replace("z_top_m = 1.2", 'z_top_m = 1.2\nremove_at_s = "soon"'), tmp_path,
        "field 'obstacle[0].remove_at_s': expected a number")


def test_the_water_mode_and_its_older_name(tmp_path):
    s, _ = load(BASE + "[controller.options]\nwater = \"still\"\n", tmp_path)
    assert s.controller_options["water"] == "still"
    bad(BASE + "[controller.options]\nwater = \"guess\"\n", tmp_path,
        "field 'controller.options.water'", "estimated")
    bad(BASE + "[controller.options]\nwater = \"true\"\nknows_current = true\n", tmp_path,
        "field 'controller.options.knows_current'", "not both")


def test_a_current_that_changes_along_the_canal(tmp_path):
    text = BASE.replace("[plant.boat]", "[current]\nprofile = [[0, 0, 0], [100, 0.1, 0.4]]\n\n"
                        "[plant.boat]")
    s, _ = load(text, tmp_path)
    field = s.current_field
    assert field.varies
    assert np.allclose(field.at(s.world.pose_at(50.0)[:2]), (0.05, 0.2))
    assert np.allclose(field.at(s.world.pose_at(300.0)[:2]), (0.1, 0.4))  # held past the end
    for profile, words in [("[[0, 0], [10, 1]]", "expected a list of [s_m, north_mps, east_mps]"),
                           ("[[10, 0, 0], [5, 1, 1]]", "must increase")]:
        bad(text.replace("[[0, 0, 0], [100, 0.1, 0.4]]", profile), tmp_path,
            "field 'current.profile'", words)
    bad(text.replace("[current]\n", "[current]\neast_mps = 0.2\n"), tmp_path,
        "field 'current.profile'", "not both")
