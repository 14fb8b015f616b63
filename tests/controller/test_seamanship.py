"""The rules of the road as the reference shaping reads them (`controller.nmpc.seamanship`):
each case one vessel on a straight or bent 20 m channel, the boat at its start."""

from dataclasses import dataclass

import numpy as np
import pytest

from controller.geometry import Polyline
from controller.nmpc.reference import WaypointPath
from controller.nmpc.seamanship import assess


@dataclass
class Track:
    id: int
    position: tuple
    velocity: tuple
    length_m: float = 7.0
    width_m: float = 2.2


def _channel(points, half_width=10.0):
    """A route through `points` (x north, y east) and its two walls, as segments (x_c, y_c,
    theta, length)."""
    pts = np.asarray(points, float)
    segs = []
    for a, b in zip(pts[:-1], pts[1:]):
        length = float(np.hypot(*(b - a)))
        theta = float(np.arctan2(*(b - a)[::-1]))
        n = np.array([-np.sin(theta), np.cos(theta)]) * half_width
        mid = 0.5 * (a + b)
        segs += [[*(mid + n), theta, length], [*(mid - n), theta, length]]
    return WaypointPath.from_polyline(Polyline(pts)), np.array(segs)


def _kind(track, points=((0, 0), (300, 0)), speed=2.0):
    path, segs = _channel(points)
    shaping = assess([track], path, 0.0, 0.0, speed, segs, hull_radius_m=2.0,
                     separation_m=2.0, vessel_separation_m=2.0, bow_m=2.0)
    return shaping.encounters[0].kind, shaping


@pytest.mark.parametrize("across", [-0.3, 0.0, 0.3])
def test_a_vessel_met_head_on_is_met_whatever_its_drift_across(across):
    """A track coming the other way 4 m to port with a few tenths of a metre a second of
    drift (a track's velocity noise) is a meeting, not a vessel crossing from port (which
    the boat would stand on for, keeping to the middle: it did, with the LiDAR, and passed
    starboard to starboard 1.3 m off)."""
    kind, shaping = _kind(Track(2, (35.0, -4.0), (-1.8, across)))
    assert kind == "meeting"
    assert shaping.offset_m > 0.0  # to starboard


def test_a_vessel_crossing_from_starboard_is_given_way_to():
    kind, shaping = _kind(Track(4, (30.0, 15.0), (0.0, -1.5)))
    assert kind == "give_way"
    assert shaping.stop_at_m is not None and shaping.stop_at_m < 30.0


def test_a_vessel_given_way_to_is_stopped_short_of_by_half_its_length():
    """A vessel crossing out of a side canal turns into the channel where it crosses, and its
    stern swings half its length toward the boat: the stop is R_b + d_v + the bow short of
    that, not of its beam (seed 1 case 3: 1.6 m from a stern turning in front of the bow)."""
    kind, shaping = _kind(Track(4, (30.0, 15.0), (0.0, -1.5), length_m=9.0, width_m=2.4))
    assert kind == "give_way"
    assert shaping.stop_at_m == pytest.approx(30.0 - (2.0 + 2.0 + 2.0 + 4.5), abs=0.5)


def test_a_vessel_crossing_from_port_is_stood_on_for():
    kind, shaping = _kind(Track(4, (30.0, -15.0), (0.0, 1.5)))
    assert kind == "stand_on"
    assert shaping.stop_at_m is None


def test_a_stand_on_vessel_acts_when_the_crosser_from_port_has_not():
    """Rule 17(b): a vessel from port still on a collision course when the boat could only
    just stop short of the crossing point: the boat stops short of it (no turn to port)."""
    kind, shaping = _kind(Track(4, (14.0, -7.0), (0.0, 1.5)))
    assert kind == "stand_on_acts"
    assert shaping.stop_at_m is not None and shaping.offset_m == 0.0
    assert "stand-on acts" in shaping.reason


def test_a_slow_vessel_on_a_straight_is_overtaken_on_its_port_side():
    kind, shaping = _kind(Track(3, (30.0, 4.0), (0.8, 0.0)))
    assert kind == "overtaking"
    assert shaping.offset_m < 0.0 and shaping.speed_mps is None


def test_no_overtaking_before_a_bend():
    """Rule 9(f): with the route turning 40 degrees 40 m on, the boat would not be past the
    vessel before the bend, so it follows it instead."""
    bend = ((0, 0), (70, 0), (70 + 100 * np.cos(0.7), 100 * np.sin(0.7)))
    kind, shaping = _kind(Track(3, (30.0, 4.0), (0.8, 0.0)), points=bend)
    assert kind == "following"
    assert shaping.speed_mps == pytest.approx(0.8)
    assert shaping.stop_at_m is not None


def test_a_vessel_given_way_to_stays_so_while_it_crosses():
    """A workboat coming out of a side canal on the port side is first seen short (its bow
    round the corner): a small craft, given way to. As its hull comes into view it is 9 m
    long, which alone would be stood on for; the decision stands (Rule 8)."""
    path, segs = _channel(((0, 0), (300, 0)))
    kw = dict(hull_radius_m=2.0, separation_m=2.0, vessel_separation_m=2.0, bow_m=2.0)
    short = assess([Track(3, (30.0, -15.0), (0.0, 1.5), length_m=3.0)], path, 0.0, 0.0, 2.0,
                   segs, **kw)
    assert short.encounters[0].kind == "give_way"
    grown = Track(3, (30.0, -12.0), (0.0, 1.5), length_m=9.0)
    assert assess([grown], path, 0.0, 0.0, 2.0, segs, **kw).encounters[0].kind == "stand_on"
    kept = assess([grown], path, 0.0, 0.0, 2.0, segs, give_way_to=frozenset({3}), **kw)
    assert kept.encounters[0].kind == "stand_on_acts" and kept.stop_at_m is not None
    gone = Track(3, (30.0, 20.0), (0.0, 1.5), length_m=9.0)  # crossed: nothing to give way to
    assert assess([gone], path, 0.0, 0.0, 2.0, segs, give_way_to=frozenset({3}),
                  **kw).encounters[0].kind != "give_way"


def test_no_overtaking_pass_on_the_side_a_vessel_given_way_to_is_crossing_to():
    """Rule 15, pass astern of the vessel given way to (fuzz seed 1, case 24): a slow launch
    to starboard would be overtaken on its port side, but a kayak drifting across toward port
    is given way to; a port pass would put the boat where the kayak is going, so the boat
    follows the launch instead. A kayak drifting toward starboard leaves the port pass."""
    path, segs = _channel(((0, 0), (300, 0)))
    kw = dict(hull_radius_m=2.0, separation_m=2.0, vessel_separation_m=2.0, bow_m=2.0)
    launch = Track(1, (30.0, 4.0), (0.8, 0.0))
    to_port = assess([launch, Track(2, (25.0, 3.0), (0.0, -0.35), 3.5, 0.8)], path, 0.0, 0.0,
                     2.0, segs, **kw)
    kinds = {e.track_id: e.kind for e in to_port.encounters}
    assert kinds == {1: "following", 2: "give_way"}
    assert to_port.offset_m == 0.0 and "clear of a vessel crossing" in to_port.reason
    to_stbd = assess([launch, Track(2, (25.0, -3.0), (0.0, 0.35), 3.5, 0.8)], path, 0.0, 0.0,
                     2.0, segs, **kw)
    kinds = {e.track_id: e.kind for e in to_stbd.encounters}
    assert kinds == {1: "overtaking", 2: "give_way"}
    assert to_stbd.offset_m < 0.0


def _overtake(tracks, **options):
    path, segs = _channel(((0, 0), (300, 0)))
    shaping = assess(tracks, path, 0.0, 0.0, 2.0, segs, hull_radius_m=2.0, separation_m=2.0,
                     vessel_separation_m=2.0, bow_m=2.0, **options)
    return {e.track_id: (e.kind, e.side) for e in shaping.encounters}, shaping


def test_a_port_pass_in_the_lane_of_oncoming_vessels_needs_the_way_seen_clear():
    """Rules 9(e) and 13 in a channel too narrow for three abreast (fuzz seed 1, case 77: a
    tour boat came round a bend into the overtaking boat): a launch 4 m to starboard leaves
    12.9 m on its port side, less than the boat and a vessel coming the other way need
    (2 R_b + 2 d_v + 5 m = 13 m). Seen 50 m ahead, an unseen vessel at 2.5 m/s could meet
    the boat before it is past, so it follows; seen 500 m ahead it overtakes."""
    launch = Track(3, (30.0, 4.0), (0.8, 0.0))
    kinds, short = _overtake([launch], sight_m=50.0)
    assert kinds == {3: ("following", "")}
    assert "seen too short" in short.reason and short.speed_mps == pytest.approx(0.8)
    kinds, far = _overtake([launch], sight_m=500.0)
    assert kinds == {3: ("overtaking", "port")} and far.offset_m < 0.0


def test_a_vessel_in_mid_channel_is_overtaken_on_its_starboard_side_out_of_that_lane():
    """A launch in mid-channel leaves 8.9 m on either side: room for the boat, not for a
    vessel coming the other way beside it too. With 50 m seen ahead the boat passes it on
    its starboard side, out of the lane of anything coming the other way."""
    kinds, shaping = _overtake([Track(3, (30.0, 0.0), (0.8, 0.0))], sight_m=50.0)
    assert kinds == {3: ("overtaking", "starboard")} and shaping.offset_m > 0.0


def test_a_vessel_close_behind_one_that_is_followed_is_followed_too():
    """A launch 13 m behind a barge that fills the channel: past the launch the boat would
    be stuck beside or behind the barge with no room to pull in, so it follows both."""
    launch = Track(1, (30.0, 4.0), (0.8, 0.0))
    barge = Track(2, (50.0, 0.0), (0.6, 0.0), length_m=7.0, width_m=8.0)
    kinds, shaping = _overtake([launch, barge])
    assert kinds == {1: ("following", ""), 2: ("following", "")}
    assert "a vessel close ahead of it is followed" in shaping.reason
    kinds, _ = _overtake([launch])
    assert kinds == {1: ("overtaking", "port")}


def test_a_side_chosen_for_overtaking_is_kept_through_a_track_s_noise():
    """A 5 m wide vessel in mid-channel leaves 7.5 m either side, less than the 8 m a pass
    needs: not overtaken. Already overtaking it on its starboard side (its track read
    narrower a moment ago), the boat keeps that side while the room stays within
    `keep_side_m` of it (Rule 8: no switching between passing and following)."""
    wide = Track(3, (30.0, 0.0), (0.8, 0.0), width_m=5.0)
    kinds, _ = _overtake([wide], sight_m=50.0)
    assert kinds == {3: ("following", "")}
    kinds, shaping = _overtake([wide], sight_m=50.0, overtaking={3: "starboard"})
    assert kinds == {3: ("overtaking", "starboard")} and shaping.offset_m > 0.0
    kinds, _ = _overtake([wide], sight_m=50.0, overtaking={3: "starboard"}, keep_side_m=0.0)
    assert kinds == {3: ("following", "")}


def test_beside_a_vessel_the_boat_falls_back_rather_than_cross_its_bow():
    """Beside a barge on its starboard side, that side closed ahead (a kayak stopped there,
    fuzz seed 1 case 109 varied), the port side open: to pass on the port side the boat
    would cut across the barge's bow (it did, into it); it falls back and follows."""
    path, segs = _channel(((0, 0), (300, 0)))
    segs = np.vstack([segs, [[10.0, 7.0, 0.0, 20.0]]])  # beside the barge, 7 m to starboard
    barge = Track(2, (3.0, 0.0), (0.6, 0.0), length_m=20.0, width_m=4.0)
    kw = dict(hull_radius_m=2.0, separation_m=2.0, vessel_separation_m=2.0, bow_m=2.0)
    beside = assess([barge], path, 0.0, 5.0, 2.0, segs, **kw)
    assert beside.encounters[0].kind == "following", beside.reason
    assert "no room on the side the boat is beside it" in beside.reason
    segs[-1, 0] = 40.0  # the same, 30 m on, and the boat astern of it: the port side will do
    astern = assess([Track(2, (40.0, 0.0), (0.6, 0.0), length_m=20.0, width_m=4.0)], path,
                    0.0, 0.0, 2.0, segs, **kw)
    assert astern.encounters[0].side == "port"
