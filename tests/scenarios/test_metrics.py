"""Metrics on hand-checked cases."""

import numpy as np
import pytest

from controller.geometry import Polyline
from scenarios.results import metrics


def test_hull_circles_sit_fore_and_aft_along_the_heading():
    c = metrics.hull_circle_centres([[10.0, 5.0, np.pi / 2]])
    assert c[0, 0] == pytest.approx([10.0, 7.0])  # bow: heading east
    assert c[0, 1] == pytest.approx([10.0, 3.0])


def test_clearance_to_two_walls():
    walls = [np.array([[-100, -6.0], [100, -6.0]]), np.array([[-100, 4.0], [100, 4.0]])]
    # heading north along the canal at y = 1: 7 m to the west wall, 3 m to the east wall
    d = metrics.clearance([[0, 1.0, 0.0]], walls)
    assert d == pytest.approx(np.array([[3.0, 3.0]]))
    # turned east: the bow circle is 1 m from the east wall, the stern 5 m from the west wall
    d = metrics.clearance([[0, 1.0, np.pi / 2]], walls)
    assert d == pytest.approx(np.array([[1.0, 5.0]]))


def test_time_below_counts_steps():
    assert metrics.time_below([5, 4.9, 3, 7, 6.99], 7.0, 0.1) == pytest.approx(0.4)


def test_control_effort_of_known_rates():
    cmds = np.array([[1.0, 0.0], [2.0, 4.0], [2.0, 4.0]])
    rates = metrics.command_rates(cmds, 0.1)
    assert rates == pytest.approx(np.array([[10, 0], [10, 40], [0, 0]]))
    assert metrics.control_effort(rates) == pytest.approx(100 + 100 + 1600)
    assert metrics.control_effort(rates, (1e-4, 1e-4)) == pytest.approx(0.18)


def test_cross_track_to_a_path():
    path = Polyline([[0, 0], [100, 0]])
    assert metrics.cross_track([[10, 2], [50, -3]], path) == pytest.approx([2, 3])


def test_timing_stats():
    s = metrics.TimingStats.of([0.001] * 99 + [0.01])
    assert s.max_ms == pytest.approx(10.0) and s.mean_ms == pytest.approx(1.09)


def test_hull_contact_sees_a_wall_inside_the_hull_rectangle():
    walls = [np.array([[-100, -6.0], [100, -6.0]]), np.array([[-100, 4.0], [100, 4.0]])]
    contact = metrics.HullContact(walls)  # 7.9 m x 2.6 m
    assert not contact.touches([0.0, 2.6, 0.0])  # side 0.1 m from the east wall
    assert contact.touches([0.0, 2.8, 0.0])  # side 0.1 m across it
    assert not contact.touches([0.0, 0.0, np.pi / 2])  # across the canal: bow 0.05 m short
    assert contact.touches([0.0, 0.1, np.pi / 2])
    # a pier end poking into the hull from the side crosses no hull edge only if inside it
    pier = [np.array([[0.5, 0.5], [0.5, 20.0]])]
    assert metrics.HullContact(pier).touches([0.0, 0.0, 0.0])
    assert not metrics.HullContact(pier).touches([0.0, -2.0, 0.0])


def _canal_with_a_step():
    """A canal along north, 14 m wide up to x = 300, then 12 m (the east wall steps in)."""
    x = np.arange(-100.0, 601.0, 2.0)
    west = np.column_stack([x, np.full(len(x), -7.0)])
    east = np.column_stack([x, np.where(x < 300, 7.0, 5.0)])
    return [west, east]


def test_canal_width_abeam_and_the_offset_from_the_middle():
    width = metrics.CanalWidth(_canal_with_a_step())
    assert width.at([50.0, 0.0, 0.0]) == pytest.approx((14.0, 14.0, 0.0))
    # 1 m east of the middle heading north: to starboard of it; heading south: to port
    assert width.at([50.0, 1.0, 0.0])[2] == pytest.approx(1.0)
    assert width.at([50.0, 1.0, np.pi])[2] == pytest.approx(-1.0)
    # turned 20 deg: still the distances to the walls, not along the beam
    assert width.at([50.0, 0.0, np.radians(20)])[0] == pytest.approx(14.0)
    assert width.at([400.0, -1.0, 0.0]) == pytest.approx((12.0, 12.0, 0.0))
    # 1 m before the step: the bow circle is already in the narrow part
    w, w_hull, _ = width.at([299.0, 0.0, 0.0])
    assert w > 12.0 and w_hull == pytest.approx(12.0)
    # open water on one side is infinitely wide (beyond reach_m)
    lone = metrics.CanalWidth([_canal_with_a_step()[0]], reach_m=30.0)
    assert lone.at([50.0, 0.0, 0.0])[0] == np.inf


def test_separation_by_place_splits_wide_and_narrow_stretches():
    clearance = np.array([[6.5, 6.6], [7.0, 6.9], [4.4, 4.5], [4.6, 4.5], [5.0, 5.1]])
    width = np.array([15.0, 15.0, 9.0, 9.0, 13.0])
    hull = np.array([15.0, 14.5, 9.0, 9.0, 9.5])  # the last: the bow in the narrow part
    offset = np.array([2.0, 0.0, 0.1, -0.3, 1.0])
    got = metrics.separation_by_place(clearance, width, hull, offset, 7.0, 0.1)
    assert got["min_clearance_where_wide_m"] == pytest.approx(6.5)
    assert got["time_narrow_s"] == pytest.approx(0.3)  # width < 14 at the boat: 3 steps
    assert got["mean_centre_offset_narrow_m"] == pytest.approx((0.1 + 0.3 + 1.0) / 3)
    assert got["max_centre_offset_narrow_m"] == pytest.approx(1.0)
    none = metrics.separation_by_place(clearance[:2], width[:2], hull[:2], offset[:2], 7.0, 0.1)
    assert none["mean_centre_offset_narrow_m"] is None and none["time_narrow_s"] == 0.0


def test_clearance_of_one_pose_is_clearance_bit_for_bit():
    """The loop's per-pose clearance (measuring only the runs of legs near the boat) gives
    exactly the numbers of measuring every leg, also far from everything and at vertices."""
    from scenarios.results.metrics import Clearance, clearance

    rng = np.random.default_rng(3)
    wall = np.column_stack([np.linspace(0, 300, 241), 8 * np.sin(np.linspace(0, 6, 241))])
    outlines = (wall, wall + (0.0, 15.0), np.array([[100, 5], [110, 5], [110, 7], [100, 7],
                                                     [100, 5.0]]))
    c = Clearance(outlines, chunk=8)
    poses = [np.array([*rng.uniform((-50, -40), (350, 60)), rng.uniform(-4, 4)])
             for _ in range(400)] + [np.array([100.0, 5.0, 0.0]), np.array([1e4, 0.0, 1.0])]
    for pose in poses:
        assert c.of(pose).tobytes() == clearance(pose[None], outlines)[0].tobytes()
    assert np.all(Clearance(()).of(poses[0]) == np.inf)


def test_an_approach_from_rest_to_the_stop_point_is_not_held():
    """Issue 34 (4): the obstruction in view at the start, the boat at rest: it first makes
    way to its stop point, and the hold counts from when it comes to rest there."""
    from scenarios.results.metrics import waiting_episodes

    speed = [0.0] * 3 + [0.5, 1.0, 1.0, 0.5, 0.2] + [0.01] * 10
    out = waiting_episodes([True] * len(speed), speed, 0.1)
    assert out["time_held_s"] == pytest.approx(1.0) and out["max_speed_while_held_mps"] == 0.01


def test_a_crawl_from_rest_is_held_and_its_creeping_counts():
    from scenarios.results.metrics import waiting_episodes

    speed = [0.0] * 3 + [0.1, 0.2, 0.15] * 5
    out = waiting_episodes([True] * len(speed), speed, 0.1)
    assert out["time_held_s"] == pytest.approx(1.8) and out["max_speed_while_held_mps"] == 0.2


def test_an_episode_under_way_is_held_from_its_first_step_at_rest():
    from scenarios.results.metrics import waiting_episodes

    speed = [2.0, 1.0, 0.5, 0.04, 0.06, 0.0] + [2.0] * 3
    out = waiting_episodes([True] * 6 + [False] * 3, speed, 0.1)
    assert out["time_waiting_s"] == pytest.approx(0.6)
    assert out["time_held_s"] == pytest.approx(0.3) and out["max_speed_while_held_mps"] == 0.06


class _Stub:
    """A vessel going north at 1 m/s from (0, 0)."""

    name = "launch"

    def pose_at(self, t):
        return np.array([t, 0.0, 0.0])

    def velocity_at(self, t):
        return np.array([1.0, 0.0])

    def outline_at(self, t):
        return np.array([[t - 4, -1], [t + 4, -1], [t + 4, 1], [t - 4, 1]], float)


def _track(id_, x, y, moving):
    from types import SimpleNamespace

    return SimpleNamespace(id=id_, position=(x, y), velocity=(0.0, 0.0), moving=moving)


def test_tracks_on_walls_and_id_switches_are_counted():
    """Issue 34 (3): a confirmed track on a wall is no boat, moving or not (its number, the
    longest and the total time); a vessel whose track id changes has switched."""
    from scenarios.results.encounters import TrackingWatch

    wall = np.array([[-50.0, 10.0], [200.0, 10.0]])
    watch = TrackingWatch([_Stub()], walls=[wall])
    for k in range(30):
        t = 0.1 * k
        tracks = [_track(1 if k < 20 else 2, t, 0.0, True),  # the launch, then a new id
                  _track(7, 30.0, 10.4, False)]  # a piece of the quay, static
        if k < 5:
            tracks.append(_track(8, 60.0, 9.2, True))  # another, moving, for 0.5 s
        watch.update(t, np.array([-20.0, 0.0, 0.0]), tracks, 0.1)
    out = watch.summary()
    assert out["wall_tracks"] == 2
    assert out["longest_wall_track_s"] == pytest.approx(3.0)
    assert out["wall_track_time_s"] == pytest.approx(3.5)
    assert out["id_switches"] == {"launch": 1}


def test_a_vessel_seen_as_two_tracks_is_a_duplicate_not_switches():
    """One vessel with two tracks at once (a hull split in two): the nearer is its track, the
    other a duplicate; the vessel's id does not switch back and forth between them."""
    from scenarios.results.encounters import TrackingWatch

    watch = TrackingWatch([_Stub()])
    for k in range(20):
        t = 0.1 * k
        near, far = (0.2, 2.0) if k % 2 else (0.3, 2.5)  # track 1 always the nearer
        tracks = [_track(2, t + far, 0.0, True), _track(1, t + near, 0.0, True)]
        watch.update(t, np.array([-20.0, 0.0, 0.0]), tracks, 0.1)
    out = watch.summary()
    assert out["id_switches"] == {"launch": 0}
    assert out["duplicate_tracks"] == 1 and out["longest_duplicate_s"] == pytest.approx(2.0)
    assert out["false_vessel_tracks"] == 0 and out["position_rms_m"] < 0.31


def test_a_track_on_a_moored_boat_beside_the_quay_is_no_wall_track():
    from scenarios.results.encounters import TrackingWatch

    wall = np.array([[-50.0, 10.0], [200.0, 10.0]])
    moored = np.array([[30.0, 7.0], [40.0, 7.0], [40.0, 9.8], [30.0, 9.8], [30.0, 7.0]])
    watch = TrackingWatch([], walls=[wall], objects=[moored])
    for k in range(20):
        watch.update(0.1 * k, np.array([0.0, 0.0, 0.0]),
                     [_track(3, 30.5, 9.3, False), _track(4, 60.0, 9.5, False)], 0.1)
    out = watch.summary()
    assert out["wall_tracks"] == 1 and out["longest_wall_track_s"] == pytest.approx(2.0)


def test_a_vessel_keeps_its_track_while_a_second_one_beside_it_is_nearer_at_times():
    """Issue 34: two tracks on one vessel, now the one now the other nearer (a hull split in
    two that flickers): the vessel keeps the id it had while that track stays on it, so no
    switch; once that track has left the vessel (beyond `match_m`), the other is its track
    and that is one switch."""
    from scenarios.results.encounters import TrackingWatch

    watch = TrackingWatch([_Stub()])
    for k in range(40):
        t = 0.1 * k
        first = t + (1.5 if k % 2 else 0.2) if k < 30 else t + 20.0  # then gone off it
        tracks = [_track(1, first, 0.0, True), _track(2, t + (0.3 if k % 2 else 1.0), 0.0, True)]
        watch.update(t, np.array([-20.0, 0.0, 0.0]), tracks, 0.1)
    out = watch.summary()
    assert out["id_switches"] == {"launch": 1}
    assert out["duplicate_tracks"] == 1 and out["longest_duplicate_s"] == pytest.approx(3.0)


def test_the_swing_while_waiting_counts_the_way_made_to_and_fro_not_the_approach():
    """A boat braking to its stop and held there, stemming a current, swings by nothing;
    one surging to and fro past its stop swings by each way back and the way made again.
    Steps outside an episode do not count."""
    from scenarios.results.metrics import waiting_episodes

    waiting = [False] * 3 + [True] * 8 + [False] * 2
    stemming = [0.35] * len(waiting)  # through the water, against a cross current
    held = np.tile([100.0, 0.0], (len(waiting), 1))
    held[:6, 0] = [90.0, 93.0, 95.0, 97.0, 98.5, 99.5]  # the approach, waiting from step 3
    held[-2:, 0] = [101.0, 102.0]  # going on, after it
    out = waiting_episodes(waiting, stemming, 0.1, xy=held)
    assert out["swing_while_waiting_m"] == pytest.approx(0.0)
    swinging = held.copy()
    swinging[3:11, 0] = [97.0, 100.0, 102.0, 100.0, 96.0, 98.0, 100.0, 101.0]
    out = waiting_episodes(waiting, stemming, 0.1, xy=swinging)
    assert out["swing_while_waiting_m"] == pytest.approx(16.0 - 4.0)
    assert "swing_while_waiting_m" not in waiting_episodes(waiting, stemming, 0.1)
