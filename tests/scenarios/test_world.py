"""The canal world: construction, validation, and the ground-truth queries."""

import math

import numpy as np
import pytest

from controller.errors import InputError
from scenarios.world.demo import demo_canal
from controller.geometry import offset_polyline, self_intersection
from scenarios.world.canal import CanalWorld, Obstacle, Wall


def straight(width=12.0, length=100.0, **kw):
    centre = np.column_stack([np.linspace(0, length, 51), np.zeros(51)])
    return CanalWorld.from_centre_line(centre, width, **kw)


def test_centre_line_gives_two_walls_at_half_width():
    world = straight(12.0)
    left, right = world.wall_polylines()
    assert np.allclose(left[:, 1], -6.0) and np.allclose(right[:, 1], 6.0)
    assert world.walls[0].land_side == "left" and world.walls[1].land_side == "right"
    assert world.length_m == pytest.approx(100.0)


def test_width_profile_is_interpolated_along_the_centre_line():
    world = straight(width=[[0.0, 10.0], [50.0, 10.0], [100.0, 20.0]])
    left, right = world.wall_polylines()
    width = right[:, 1] - left[:, 1]
    assert width[0] == pytest.approx(10.0) and width[25] == pytest.approx(10.0)
    assert width[-1] == pytest.approx(20.0) and width[38] == pytest.approx(15.2, abs=1e-6)


def test_per_bank_heights_and_backdrop_behind_the_land_side():
    world = straight(12.0, wall_height_m=(1.2, 2.5), setback_m=(4.0, 6.0),
                     backdrop_height_m=(9.0, 0.0))
    left, right = world.walls
    assert (left.height_m, right.height_m) == (1.2, 2.5)
    assert np.allclose(left.backdrop[:, 1], -10.0)  # 4 m behind the west wall, on land
    assert right.backdrop is None  # open land: nothing taller than the quay


def test_offset_polyline_keeps_legs_parallel_at_a_corner():
    pts = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    off = offset_polyline(pts, 1.0)  # to the right of travel: east of the first leg
    assert np.allclose(off[0], [0.0, 1.0]) and np.allclose(off[2], [9.0, 10.0])
    assert np.allclose(off[1], [9.0, 1.0])  # mitred corner, both legs stay 1 m away


def test_segments_near_are_clipped_to_the_circle():
    world = straight(10.0)
    segs = world.segments_near((50.0, 0.0), 10.0)
    assert len(segs) > 0
    total = segs[:, 3].sum()
    assert total == pytest.approx(2 * 2 * math.sqrt(10.0**2 - 5.0**2), rel=1e-9)
    centres = segs[:, :2]
    assert np.all(np.hypot(centres[:, 0] - 50.0, centres[:, 1]) <= 10.0)


def test_bridge_is_left_out_below_its_deck():
    deck = Obstacle([[40, -10], [44, -10], [44, 10], [40, 10]], z_top_m=4.0, z_bottom_m=3.0,
                    kind="bridge", name="deck")
    world = straight(10.0, obstacles=(deck,))
    assert len(world.surfaces()) == 3
    assert len(world.surfaces(air_draft_m=2.5)) == 2
    assert world.clearance([[42.0, 0.0]])[0] == pytest.approx(0.0, abs=1e-9)
    assert world.clearance([[42.0, 0.0]], air_draft_m=2.5)[0] == pytest.approx(5.0)


def test_clearance_is_distance_to_the_nearest_surface():
    pier = Obstacle([[30, -5], [32, -5], [32, -2], [30, -2]], name="pier")
    world = straight(10.0, obstacles=(pier,))
    d = world.clearance([[50.0, 0.0], [31.0, 0.0], [31.0, -3.0]])
    assert d == pytest.approx([5.0, 2.0, 0.0])  # inside the pier: a collision
    assert pier.contains([[31.0, -3.0], [31.0, 0.0]]).tolist() == [True, False]


def test_line_of_sight_is_blocked_by_a_pier():
    pier = Obstacle([[30, -5], [32, -5], [32, -2], [30, -2]], name="pier")
    world = straight(10.0, obstacles=(pier,))
    pts, theta, edge = world.surface_samples((31.0, 0.0), 30.0)
    los = world.line_of_sight([[31.0, 0.0]], pts, edge)[:, 0]
    behind = (pts[:, 1] < -4.9) & (np.abs(pts[:, 0] - 31.0) < 0.9)  # west wall behind the pier
    assert behind.any() and not los[behind].any()
    across = pts[:, 1] > 4.9
    assert los[across].all()
    # Samples stand for 0.25 m each and follow the surfaces' directions.
    on_wall = np.abs(pts[:, 1] - 5.0) < 1e-9
    assert np.allclose(np.abs(theta[on_wall]), 0.0)


def test_pose_at_follows_the_centre_line_and_offsets_to_starboard():
    world = straight(10.0)
    x, y, psi = world.pose_at(20.0, offset_m=2.0)
    assert (x, y, psi) == pytest.approx((20.0, 2.0, 0.0))
    with pytest.raises(InputError, match="outside 0..100.0 m"):
        world.pose_at(150.0)


def test_self_intersection_is_found():
    assert self_intersection([[0, 0], [10, 0], [10, 10], [5, -5]]) is not None
    assert self_intersection([[0, 0], [10, 0], [10, 10], [0, 10]]) is None


# -- bad input ----------------------------------------------------------------------------
def test_self_intersecting_wall_is_an_error_naming_it():
    with pytest.raises(InputError, match=r"wall 'quay': points: the wall crosses itself \(legs 0 and 2\)"):
        Wall([[0, 0], [10, 0], [10, 10], [5, -5]], name="quay")


@pytest.mark.parametrize("kw,match", [
    ({"points": [[0, 0]]}, "at least 2 points"),
    ({"points": [[0, 0], [1, np.nan]]}, "not finite"),
    ({"points": [[0, 0], [0, 0], [1, 1]]}, "repeated point"),
    ({"points": [[0, 0, 0], [1, 1, 1]]}, r"\[x, y\] points"),
    ({"height_m": 0.0}, "height_m: must be > 0"),
    ({"land_side": "port"}, "land_side must be 'left' or 'right'"),
    ({"setback_m": -1.0}, "setback_m"),
])
def test_bad_wall_fields_are_named(kw, match):
    args = {"points": [[0, 0], [10, 0]], **kw}
    with pytest.raises(InputError, match=match):
        Wall(**args)


@pytest.mark.parametrize("kw,match", [
    ({"z_top_m": 1.0, "z_bottom_m": 2.0}, "z_top_m .* must be above z_bottom_m"),
    ({"kind": "whale"}, "kind must be one of"),
    ({"outline": [[0, 0], [1, 0]]}, "at least 3 points"),
    ({"outline": [[0, 0], [2, 2], [2, 0], [0, 2]]}, r"obstacle 'p': outline: crosses itself"),
    ({"outline": [[0, 0], [1, 1], [3, 3]]}, r"obstacle 'p': outline: encloses no area"),
    ({"outline": [[0, 0], [2, 0], [0, 0]]}, r"obstacle 'p': outline: encloses no area"),
])
def test_bad_obstacle_fields_are_named(kw, match):
    args = {"outline": [[0, 0], [2, 0], [2, 2], [0, 2]], "name": "p", **kw}
    with pytest.raises(InputError, match=match):
        Obstacle(**args)


def test_bad_width_profile_is_named():
    centre = [[0, 0], [100, 0]]
    with pytest.raises(InputError, match="width_m: the s_m values must increase"):
        CanalWorld.from_centre_line(centre, [[50, 10], [10, 12]])
    with pytest.raises(InputError, match="width_m"):
        CanalWorld.from_centre_line(centre, -3.0)


def test_two_walls_that_cross_each_other_are_named():
    west = Wall([[0, -5], [50, -5], [100, 8]], name="west quay")
    east = Wall([[0, 5], [100, 5]], land_side="right", name="east quay")
    with pytest.raises(InputError, match=r"walls 'west quay' and 'east quay' cross each other "
                                         r"\(their legs 1 and 0\)") as err:
        CanalWorld.from_walls([west, east])
    assert err.value.walls == (0, 1) and err.value.key == "walls"


def test_walls_crossing_through_a_vertex_and_a_wall_touching_itself_are_errors():
    west = Wall([[0, -5], [50, 5], [100, 10]], name="west")  # its vertex lies on the east wall
    east = Wall([[0, 5], [100, 5]], land_side="right", name="east")
    with pytest.raises(InputError, match="walls 'west' and 'east' cross each other"):
        CanalWorld.from_walls([west, east])
    with pytest.raises(InputError, match=r"wall 'loop': points: the wall crosses itself \(legs 0 and 4\)"):
        Wall([[0, 0], [10, 0], [20, 0], [20, 10], [10, 10], [10, -10]], name="loop")


def test_walls_meeting_end_to_end_are_not_a_crossing():
    a = Wall([[0, -5], [50, -5]], name="a")
    b = Wall([[50, -5], [100, -6]], name="b")
    c = Wall([[0, 5], [100, 5]], land_side="right", name="c")
    d = Wall([[30, 5], [30, 9]], land_side="right", name="d")  # ends on c: a side quay
    assert len(CanalWorld.from_walls([a, b, c, d]).walls) == 4


@pytest.mark.parametrize("centre, width, words", [
    # a sharp 90-degree corner resampled every 2 m: the inner wall runs back at the corner
    (np.vstack([np.column_stack([np.arange(0, 101, 2.0), np.zeros(51)]),
                np.column_stack([np.full(50, 100.0), np.arange(2, 101, 2.0)])]), 16.0,
     ["right wall folds back", "s = 98 m", "half the width (8.0 m)", "corner_radius_m"]),
    # a U-turn of radius 5 m in a 16 m canal: north along y = 0, back south along y = 10
    (np.vstack([np.column_stack([np.linspace(0, 50, 26), np.zeros(26)]),
                np.column_stack([50 + 5 * np.cos(np.linspace(-np.pi / 2, np.pi / 2, 17)[1:-1]),
                                 5 + 5 * np.sin(np.linspace(-np.pi / 2, np.pi / 2, 17)[1:-1])]),
                np.column_stack([np.linspace(50, 0, 26), np.full(26, 10.0)])]), 16.0,
     ["right wall folds back", "near s = 50 m", "width_m / width_profile"]),
])
def test_offset_walls_that_fold_at_a_tight_bend_are_an_error(centre, width, words):
    with pytest.raises(InputError) as err:
        CanalWorld.from_centre_line(centre, width, name="tight")
    msg = str(err.value)
    assert msg.startswith("canal 'tight': centre_line: ") and err.value.key == "centre_line"
    for w in words:
        assert w in msg, msg


def test_a_canal_coming_back_within_its_width_has_crossing_walls():
    # north to (0, 0), a starboard loop of radius 30 m, then west across the first straight
    phi = np.linspace(0, 1.5 * np.pi, 120)[1:]
    centre = np.vstack([np.column_stack([np.linspace(-60, 0, 31), np.zeros(31)]),
                        np.column_stack([30 * np.sin(phi), 30 - 30 * np.cos(phi)]),
                        np.column_stack([np.full(25, -30.0), np.linspace(28, -20, 25)])])
    with pytest.raises(InputError, match="cross") as err:
        CanalWorld.from_centre_line(centre, 12.0)
    assert err.value.key == "centre_line"


def test_a_gentle_bend_does_not_fold():
    arc = np.linspace(0, np.pi / 2, 60)
    centre = np.column_stack([40 * np.sin(arc), 40 * (1 - np.cos(arc))])
    assert len(CanalWorld.from_centre_line(centre, 16.0).walls) == 2


def test_off_water_in_a_straight_canal():
    pier = Obstacle([[30, -8], [34, -8], [34, -5], [30, -5]], name="pier")
    world = straight(16.0, obstacles=(pier,))
    reasons = world.off_water([[50, 0], [50, 20], [50, 8], [0, 0], [0, 7.9], [300, 0],
                               [-200, 0], [32, -6], [100, 0], [0, 9]])
    assert reasons == [None, "outside the canal", "on wall 'right'", None, None,
                       "outside the canal", "outside the canal", "inside obstacle 'pier'", None,
                       "outside the canal"]


def test_off_water_with_two_explicit_walls_in_either_direction():
    west = Wall([[0, -8], [100, -8]], name="west")
    east = Wall([[100, 8], [0, 8]], land_side="left", name="east")  # drawn the other way
    world = CanalWorld.from_walls([west, east])
    assert world.water_ring is not None and len(world.water_ring) == 4
    assert world.off_water([[50, 0], [50, 10], [150, 0], [50, -8]]) == [
        None, "outside the canal", "outside the canal", "on wall 'west'"]


def test_off_water_without_a_water_ring_goes_from_the_centre_line():
    # three walls: the east bank in two pieces
    west = Wall([[0, -8], [100, -8]], name="west")
    east1 = Wall([[0, 8], [50, 8]], land_side="right", name="east 1")
    east2 = Wall([[50, 8], [100, 8]], land_side="right", name="east 2")
    world = CanalWorld.from_walls([west, east1, east2], centre_line=[[0, 0], [100, 0]])
    assert world.water_ring is None
    # through the vertex where the two pieces meet, through a resampled vertex, past the end
    assert world.off_water([[50, 20], [50, 0], [20, 3], [300, 0], [-5, 0]]) == [
        "outside the canal", None, None, "outside the canal", "outside the canal"]


def test_a_world_needs_a_wall():
    with pytest.raises(InputError, match="at least one wall"):
        CanalWorld.from_walls([])


# -- the demo canal -------------------------------------------------------------------------
def test_demo_canal_has_bends_width_changes_and_a_pier():
    world = demo_canal()
    assert 300.0 <= world.length_m <= 500.0
    kinds = {o.kind for o in world.obstacles}
    assert {"pier", "boat", "bridge"} <= kinds
    # Width changes: distance between the banks along the centre line varies by > 5 m.
    s = np.linspace(0, world.length_m, 80)
    widths = [2 * world.clearance([world.pose_at(v)[:2]], air_draft_m=0.0)[0] for v in s]
    assert max(widths) - min(widths) > 5.0
    # Bends: the heading turns both ways by more than 45 deg.
    psi = np.unwrap([world.pose_at(v)[2] for v in s])
    assert np.max(np.diff(psi)) > 0 and np.min(np.diff(psi)) < 0 and np.ptp(psi) > math.radians(45)
    # Wall heights in the paper's 1-3 m range; banks without gaps.
    assert all(1.0 <= w.height_m <= 3.0 for w in world.walls)
    for a, b in zip(world.walls[:2], world.walls[1:3]):
        assert np.allclose(a.points[-1], b.points[0])


def test_two_walls_that_are_not_the_two_banks_of_one_stretch_make_no_ring():
    """A quay opposite a longer wall, or one bank in two pieces: a ring through their ends
    would cut off open water, so the points go by the water side of the nearest wall."""
    west = Wall([[0, -10], [100, -10]], name="west")
    quay = Wall([[40, 10], [60, 10]], land_side="right", name="quay")
    world = CanalWorld.from_walls([west, quay])
    assert world.water_ring is None
    assert world.off_water([[10, 0], [90, 0], [50, 12], [50, -12], [150, 0]]) == [
        None, None, "outside the canal", "outside the canal", None]
    piece_a = Wall([[-10, 10], [50, 10]], land_side="right", name="a")
    piece_b = Wall([[50, 10], [110, 20]], land_side="right", name="b")
    world = CanalWorld.from_walls([piece_a, piece_b])
    assert world.water_ring is None
    # behind the corner where the pieces meet: outside, whichever leg is nearer
    assert world.off_water([[5, 0], [95, 0], [50, 11], [80, 20], [52, 10.5]]) == [
        None, None, "outside the canal", "outside the canal", "outside the canal"]


@pytest.mark.parametrize("reverse", [False, True])
def test_walls_that_meet_at_one_end_leave_the_other_end_open(reverse):
    """A dead end at the south: the walls meet there, the north end is the open one, however
    the walls are drawn."""
    west = [[-10, 0], [-10, -10], [110, -10]]
    east = [[-10, 0], [-10, 10], [110, 10]]
    sides = ("left", "right")
    if reverse:
        west, east, sides = west[::-1], east[::-1], ("right", "left")
    world = CanalWorld.from_walls([Wall(west, land_side=sides[0], name="west"),
                                   Wall(east, land_side=sides[1], name="east")])
    assert world.water_ring is not None
    assert world.off_water([[5, 0], [110, 0], [111, 0], [-11, 0]]) == [
        None, None, "outside the canal", "outside the canal"]


def test_an_obstacle_removed_at_a_time_is_present_before_it_only():
    ob = Obstacle([[0, 0], [1, 0], [1, 1]], remove_at_s=30.0, name="barge")
    assert ob.present_at(29.9) and not ob.present_at(30.0)
    world = CanalWorld.from_centre_line([[0, 0], [100, 0]], 10.0, obstacles=(ob,))
    assert world.changes
    assert world.obstacles_present(0.0).tolist() == [True]
    assert world.obstacles_present(31.0).tolist() == [False]
    with pytest.raises(InputError, match="remove_at_s"):
        Obstacle([[0, 0], [1, 0], [1, 1]], remove_at_s=-1.0)
