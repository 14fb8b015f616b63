"""The NMPC's reference: forward search, across legs, unwrapped heading, stop at the end."""

import math

import numpy as np
import pytest

from controller.errors import InputError
from controller.nmpc.reference import reference_trajectory, waypoint_path

NP, TS = 25, 1.0


def test_straight_path_reference_advances_at_target_speed():
    path = waypoint_path([[0, 0], [200, 0]])
    ref = reference_trajectory(path, [10.0, 3.0], 0.0, 2.0, NP, TS)
    assert ref.progress_m == pytest.approx(10.0)
    assert ref.cross_track_m == pytest.approx(3.0)
    assert np.allclose(ref.states[:, 0], 10.0 + 2.0 * np.arange(NP + 1))
    assert np.allclose(ref.states[:, 1], 0.0)
    assert np.allclose(ref.states[:, 3], 2.0)
    assert np.allclose(ref.states[:, 4:], 0.0)


def test_reference_runs_across_legs_with_each_legs_heading():
    # north 20 m, then east: the 50 m horizon crosses the corner
    path = waypoint_path([[0, 0], [20, 0], [20, 100]])
    ref = reference_trajectory(path, [10.0, 0.0], 0.0, 2.0, NP, TS)
    xy, psi = ref.states[:, :2], ref.states[:, 2]
    before = xy[:, 0] < 20 - 1e-9
    assert np.allclose(psi[before], 0.0)
    assert np.allclose(psi[~before], math.pi / 2)
    # r_10 is 20 m along: 10 m to the corner, then 10 m east
    assert xy[10] == pytest.approx([20.0, 10.0])


def test_forward_search_keeps_an_s_bend_from_jumping_back():
    # a hairpin: out north 50 m, back south 4 m to the east; the boat on the way out is
    # nearer the return leg's later part than nothing - but progress keeps it on leg one
    path = waypoint_path([[0, 0], [50, 0], [50, 4], [0, 4]])
    ref = reference_trajectory(path, [40.0, 3.0], 0.0, 2.0, NP, TS, progress_m=35.0,
                               search_ahead_m=20.0)
    assert ref.progress_m == pytest.approx(40.0)  # on the outbound leg, not the return one
    unconstrained = reference_trajectory(path, [40.0, 3.0], 0.0, 2.0, NP, TS)
    assert unconstrained.progress_m > 54  # what a plain closest-point search would pick
    # and progress never runs backwards even when the boat falls behind it
    behind = reference_trajectory(path, [30.0, 0.0], 0.0, 2.0, NP, TS, progress_m=35.0,
                                  search_ahead_m=20.0)
    assert behind.progress_m == pytest.approx(35.0)


def test_heading_is_unwrapped_against_the_boats_heading():
    # a path heading south (psi = pi), boat heading just below pi or at -pi + 0.05
    path = waypoint_path([[100, 0], [0, 0]])
    for boat in (math.pi - 0.05, -math.pi + 0.05, 3 * math.pi - 0.05):
        ref = reference_trajectory(path, [90.0, 0.0], boat, 2.0, NP, TS)
        assert abs(ref.states[0, 2] - boat) < 0.1
    # through a turn across +-pi the reference heading stays continuous
    turn = waypoint_path([[0, 0], [-20, 1], [-40, -1]])
    ref = reference_trajectory(turn, [-5.0, 0.2], math.pi, 2.0, NP, TS)
    assert np.abs(np.diff(ref.states[:, 2])).max() < 0.2


def test_reference_stops_at_the_last_waypoint():
    path = waypoint_path([[0, 0], [30, 0]])
    ref = reference_trajectory(path, [20.0, 0.0], 0.0, 2.0, NP, TS)
    assert np.allclose(ref.states[6:, 0], 30.0)
    assert np.allclose(ref.states[5:, 3], 0.0)  # speed 0 from the end on
    assert ref.states[4, 3] == 2.0
    end = reference_trajectory(path, [35.0, 0.0], 0.0, 2.0, NP, TS)
    assert end.at_end and np.allclose(end.states[:, 0], 30.0)


@pytest.mark.parametrize("waypoints, words", [
    ([], "empty"),
    ([[0.0, 0.0]], "two distinct"),
    ([[0.0, 0.0], [0.0, 0.0]], "two distinct"),
    ([[0.0, 0.0], [float("nan"), 1.0]], "NaN"),
    ([1.0, 2.0, 3.0], "shape"),
])
def test_bad_waypoints_are_clear_errors(waypoints, words):
    with pytest.raises(InputError, match=words):
        waypoint_path(waypoints)


def test_negative_target_speed_is_an_error():
    with pytest.raises(InputError, match="target speed"):
        reference_trajectory(waypoint_path([[0, 0], [1, 0]]), [0, 0], 0.0, -1.0, NP, TS)


def test_a_slow_down_ahead_brakes_the_reference_along_the_horizon():
    """`slow_to`: the reference keeps its speed until braking at `decel_mps2` brings it to
    the slow speed where asked, then goes on at that speed; with a stop too, it rests there."""
    path = waypoint_path([[0.0, 0.0], [200.0, 0.0]])
    ref = reference_trajectory(path, [0.0, 0.0], 0.0, 2.0, NP, TS, decel_mps2=0.1,
                               slow_to=(40.0, 1.0))
    speed = ref.states[:, 3]
    assert speed[0] == pytest.approx(2.0)
    assert np.all(np.diff(speed) <= 1e-9)
    x = ref.states[:, 0]
    assert np.all(speed[x >= 40.5] == pytest.approx(1.0, abs=0.02))
    braking = (x > 30.0) & (x < 39.0)  # v^2 = 1 + 2 a (40 - s) on the way down
    assert np.allclose(speed[braking] ** 2, 1.0 + 0.2 * (40.0 - x[braking]), atol=0.05)
    stopped = reference_trajectory(path, [0.0, 0.0], 0.0, 2.0, NP, TS, stop_at_m=30.0,
                                   decel_mps2=0.1, slow_to=(40.0, 1.0))
    assert stopped.states[-1, 0] == pytest.approx(30.0, abs=0.3)
    assert stopped.states[-1, 3] == pytest.approx(0.0, abs=0.2)


def test_a_boat_past_a_blocked_way_stop_is_brought_back_to_it():
    """A boat that drifted past its stop holds where it is, or, waiting for a blocked way
    (`back_to_stop`), is asked back to the stop, astern at 0.5 m/s and braking to rest there
    (not all at once: a boat 3 m past was driven back at 1.8 m/s, 26 m past the stop)."""
    path = waypoint_path([[0.0, 0.0], [200.0, 0.0]])
    held = reference_trajectory(path, [42.0, 0.0], 0.0, 2.0, NP, TS, stop_at_m=40.0)
    assert np.allclose(held.states[:, 0], 42.0)
    back = reference_trajectory(path, [42.0, 0.0], 0.0, 2.0, NP, TS, stop_at_m=40.0,
                                back_to_stop=True)
    x, u = back.states[:, 0], back.states[:, 3]
    assert x[0] == pytest.approx(42.0) and np.all(np.diff(x) <= 1e-12) and x[-1] < 41.9
    assert np.all(x >= 40.0 - 1e-9) and np.all((u <= 0.0) & (u >= -0.5))  # astern, gently
    near = reference_trajectory(path, [40.3, 0.0], 0.0, 2.0, NP, TS, stop_at_m=40.0,
                                back_to_stop=True, decel_mps2=0.15)
    assert near.states[-1, 0] == pytest.approx(40.0, abs=1e-6)  # braked to rest at the stop
    assert near.states[-1, 3] == pytest.approx(0.0, abs=1e-6)
    assert back.progress_m == pytest.approx(42.0)


def test_a_reference_moving_across_the_path_heads_along_its_line():
    """An offset that changes along the path (moving over to a gap beside an obstruction)
    turns the reference heading along the line it draws: with the leg's heading across a
    ramp, a boat stopped behind a kayak at 0.5 m/s held that heading against the move over
    and never went round (`drifting_kayak_at_a_junction_while_overtaking`)."""
    path = waypoint_path([[0.0, 0.0], [200.0, 0.0]])

    def ramp(s):  # 5 m to starboard over 20 m, from 10 m to 30 m along
        return 5.0 * np.clip((np.asarray(s, float) - 10.0) / 20.0, 0.0, 1.0)

    ref = reference_trajectory(path, [0.0, 0.0], 0.0, 2.0, NP, TS, offset_m=ramp)
    xy, psi = ref.states[:, :2], ref.states[:, 2]
    line = np.arctan2(np.gradient(xy[:, 1]), np.gradient(xy[:, 0]))
    on_ramp = (xy[:, 0] > 11.0) & (xy[:, 0] < 29.0)
    assert on_ramp.sum() >= 5
    assert np.allclose(psi[on_ramp], math.atan(0.25))
    assert np.allclose(psi[on_ramp], line[on_ramp], atol=1e-6)
    assert np.allclose(psi[xy[:, 0] > 31.0], 0.0)  # along the leg again past the ramp
    fixed = reference_trajectory(path, [0.0, 0.0], 0.0, 2.0, NP, TS, offset_m=3.0)
    assert np.allclose(fixed.states[:, 2], 0.0)  # a constant offset: the leg's heading
