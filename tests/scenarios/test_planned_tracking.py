"""The baselines' tracked path: the plan, then the waypoints beyond its end."""

import numpy as np

from controller.params import IDENTIFIED
from scenarios.loop.controllers import PlannedLosPid

WAYPOINTS = np.array([[0.0, 0.0], [100.0, 0.0], [200.0, 50.0]])


def test_a_plan_is_continued_by_the_waypoints_beyond_its_end():
    tracker = PlannedLosPid("test", None, IDENTIFIED, WAYPOINTS, 2.0)
    plan = np.array([[10.0, 1.0], [50.0, 2.0], [90.0, 0.5]])
    joined = tracker._then_waypoints(plan)
    assert np.array_equal(joined[:3], plan)
    assert np.array_equal(joined[3:], WAYPOINTS[1:])
    # a plan that reaches the last waypoint is tracked as it is
    end = np.array([[150.0, 20.0], [199.0, 50.0]])
    assert np.array_equal(tracker._then_waypoints(end), end)


def test_a_kept_plan_that_runs_out_does_not_turn_the_boat_around():
    """The planner fails after its first plan: the tracker goes on along the waypoints."""
    first = np.array([[0.0, 0.0], [30.0, 0.0]])
    calls = []

    def planner(state, actuators, segments, blind):
        calls.append(state[0])
        if len(calls) == 1:
            return first, True, "ok", None
        return None, False, "infeasible", None

    tracker = PlannedLosPid("test", planner, IDENTIFIED, WAYPOINTS, 2.0)
    state = np.array([45.0, 0.0, 0.0, 2.0, 0.0, 0.0])  # beyond the plan's end, heading on
    tracker.step(0.0, state, np.zeros(2), np.empty((0, 4)))
    nS = [tracker.step(0.1 * k, state, np.zeros(2), np.empty((0, 4))).command[1]
          for k in range(1, 5)][-1]
    assert abs(nS) < 10.0  # no hard turn back toward the plan's end
