"""`check_criteria` on made-up summaries: each criterion passes, fails with a sentence that
names it, and fails when the run never reached the kind of place it is about."""

from dataclasses import replace

import pytest

from scenarios.loop.runner import check_criteria
from scenarios.scenario_file import Criteria, parse_scenario

BASE = """
[scenario]
duration_s = 100
[canal]
centre_line = [[0, 0], [200, 0]]
width_m = 16
[route]
waypoints = [[10, 0], [190, 0]]
"""

SUMMARY = {
    "reached_goal": True, "status": "reached goal", "final_distance_to_goal_m": 3.0,
    "duration_s": 80.0, "min_clearance_m": 5.5, "time_below_desired_s": 12.0,
    "mean_cross_track_m": 0.4, "narrow_below_m": 10.0, "min_clearance_where_wide_m": 4.6,
    "mean_centre_offset_narrow_m": 0.05,
}


@pytest.fixture(scope="module")
def scenario():
    return parse_scenario(BASE, "base.toml")


@pytest.mark.parametrize("criteria, changes, words", [
    (Criteria(reach_goal=True), {"reached_goal": False, "status": "time limit"},
     "did not reach the goal (time limit, 3.0 m from it)"),
    (Criteria(reach_goal_within_s=70.0), {}, "after 80.0 s > 70.0 s"),
    (Criteria(min_clearance_m=6.0), {}, "min clearance 5.5 m < 6.0 m"),
    (Criteria(max_time_below_desired_s=10.0), {}, "12.0 s below the desired separation"),
    (Criteria(max_mean_cross_track_m=0.3), {}, "mean cross-track 0.4 m > 0.3 m"),
    (Criteria(min_clearance_where_wide_m=4.8), {},
     "where the canal is at least 10 m wide 4.6 m < 4.8 m"),
    (Criteria(max_mean_centre_offset_narrow_m=0.01), {},
     "narrower than 10 m 0.05 m > 0.01 m"),
    (Criteria(min_clearance_where_wide_m=4.0), {"min_clearance_where_wide_m": None},
     "never where the canal is at least 10 m wide"),
    (Criteria(max_mean_centre_offset_narrow_m=0.5), {"mean_centre_offset_narrow_m": None},
     "never where the canal is narrower than 10 m"),
])
def test_a_failed_criterion_is_one_sentence_naming_it(scenario, criteria, changes, words):
    summary = {**SUMMARY, **changes}
    failed = check_criteria(replace(scenario, criteria=criteria), summary)
    assert len(failed) == 1 and words in failed[0]


def test_met_criteria_give_no_sentence(scenario):
    met = Criteria(reach_goal=True, reach_goal_within_s=90.0, min_clearance_m=5.0,
                   max_time_below_desired_s=15.0, max_mean_cross_track_m=0.5,
                   min_clearance_where_wide_m=4.3, max_mean_centre_offset_narrow_m=0.5)
    assert check_criteria(replace(scenario, criteria=met), SUMMARY) == []
    # criteria left out are not checked, whatever the summary says
    bad = {**SUMMARY, "min_clearance_m": 0.1, "min_clearance_where_wide_m": None}
    assert check_criteria(replace(scenario, criteria=Criteria(reach_goal=True)), bad) == []


@pytest.mark.parametrize("criteria, changes, words", [
    (dict(max_fallback_steps=0), dict(fallback_steps=2), "2 steps on a fallback plan > 0"),
    (dict(min_time_held_s=20.0), dict(time_held_s=5.0), "held at rest for 5.0 s < 20.0 s"),
    (dict(max_speed_while_held_mps=0.1), dict(max_speed_while_held_mps=0.3),
     "speed while held 0.3 m/s > 0.1 m/s"),
    (dict(max_swing_while_waiting_m=5.0), dict(swing_while_waiting_m=183.0),
     "swung 183.0 m to and fro while waiting > 5.0 m"),
    (dict(min_first_detected_m=40.0),
     dict(obstacles=[{"name": "pier", "first_detected_m": 12.5}]),
     "obstacle 'pier' first detected 12.5 m away (< 40.0 m)"),
    (dict(min_first_detected_m=40.0), dict(obstacles=[{"name": "pier", "first_detected_m": None}]),
     "obstacle 'pier' first detected never"),
])
def test_the_waiting_and_detection_criteria_name_what_failed(scenario, criteria, changes, words):
    failed = check_criteria(replace(scenario, criteria=Criteria(**criteria)),
                            {**SUMMARY, **changes})
    assert len(failed) == 1 and words in failed[0]
