"""Encounters written against the controller failures of issue 34 (1), kept as regression
tests: each scenario file under tests/scenarios/encounters/ runs with its own perception
(known walls: the vessel handed over at once, with its velocity) and with the LiDAR, and must
end with no controller failure and no collision, its criteria met."""

import csv
from dataclasses import replace
from pathlib import Path

import pytest

from scenarios.loop.runner import check_criteria, run_scenario
from scenarios.scenario_file import load_scenario

FILES = sorted((Path(__file__).parent / "encounters").glob("*.toml"))
REGRESSIONS = Path(__file__).parent / "regressions"


def with_options(scenario, **options):
    """The scenario with these controller options on top of its own."""
    return replace(scenario, controller_options={**scenario.controller_options, **options})


# The default tests must end within 10 minutes on CI's machine, which runs them at half the
# speed of a fast day (711 s with every fuzz case's rerun in them, 2026-12-07). Runs of more
# than about 15 s of CPU there are in the slow set (`pytest -m slow`, run before an issue is
# closed): the encounters below, and the fuzz cases' reruns marked slow with their time. The
# default set keeps a run of each kind: known walls and LiDAR, a stop, a hard QP failed.
LONG_RUNS = {"following_a_barge_meeting_a_launch", "drifting_kayak_at_a_junction_while_overtaking",
             "meeting_round_a_bend_while_following", "overtaking_before_a_bend_meeting_a_tour_boat"}


def _encounter(path):
    marks = [pytest.mark.slow] if path.stem in LONG_RUNS else []
    return pytest.param(path, id=path.stem, marks=marks)


@pytest.mark.parametrize("perception", [
    "known-walls", pytest.param("lidar", marks=pytest.mark.slow)])
@pytest.mark.parametrize("path", [_encounter(f) for f in FILES])
def test_encounter_ends_without_a_controller_failure(path, perception, tmp_path):
    scenario = replace(load_scenario(path), perception=perception)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert not summary["status"].startswith("controller failed"), summary["status"]
    assert not summary["collision"], summary["status"]
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)


def test_meeting_round_a_bend_while_following_fails_the_hard_qp(tmp_path):
    """An encounter that is a real test of the exact penalty: with the paper's hard
    obstacle rows the same run ends with a controller failure. (Following a barge while
    meeting a launch was one until the lanes were taken from where the vessel will be, and
    the workboat from port while known walls handed the workboat over through the
    buildings, 59 m off.)"""
    scenario = load_scenario(Path(__file__).parent / "encounters"
                             / "meeting_round_a_bend_while_following.toml")
    hard = with_options(scenario, obstacle_rows="hard")
    summary = run_scenario(hard, tmp_path, plots=False).summary
    assert summary["status"].startswith("controller failed")


@pytest.mark.slow  # (24 s: a whole fuzz case's run; see LONG_RUNS)
def test_a_plan_breaking_its_rows_far_is_solved_again_from_the_reference(tmp_path):
    """A kayak drifting across from starboard with the current astern (fuzz seed 4 case 15,
    known walls): the real-time iteration kept its plan of passing ahead of the kayak,
    breaking the obstacle rows by up to 10 units and coming within 0.27 m of it; solved
    again from the reference, the boat gives way and keeps 2 m."""
    scenario = load_scenario(REGRESSIONS / "kayak_drifting_across_with_the_current_astern.toml")
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert summary["elastic"]["restarts"] >= 1
    assert not check_criteria(scenario, summary)
    off = with_options(scenario, restart_elastic_h=0.0, restart_broken_s=0.0)
    assert check_criteria(off, run_scenario(off, tmp_path / "off", plots=False).summary)


HELD_BEHIND_A_KAYAK = (REGRESSIONS
                       / "boat_held_at_rest_behind_a_kayak_stopped_across_the_canal.toml")
HELD_UNTIL_BACKING_OFF = (REGRESSIONS
                          / "boat_held_at_rest_until_it_backs_off_from_a_stopped_kayak.toml")


@pytest.mark.slow  # (2 x 33 s: a whole fuzz case's run, twice; see LONG_RUNS)
def test_a_plan_that_holds_the_boat_at_rest_is_made_again_from_the_reference(tmp_path):
    """A kayak stopped across half a narrow canal, the boat come up to it behind a barge
    (fuzz seed 1 case 47, known walls; its sides walls like any others, `rest_keep_m` 0:
    grown by 1.5 m they leave no way past, and the boat waits). With the reference's heading
    along the line over to the gap the boat goes round on its first plans. With the leg's
    heading (`heading_along_line` false, as before) the real-time iteration's plan held the
    boat at rest beside the gap; planned again from the reference once it had for 5 s (or,
    where that finds nothing, backed off for a new run at it), it goes round and reaches
    the goal."""
    scenario = with_options(load_scenario(HELD_BEHIND_A_KAYAK), rest_keep_m=0.0)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert summary["elastic"]["restarts"] + summary["elastic"]["back_offs"] == 0
    assert not check_criteria(scenario, summary)
    leg = with_options(scenario, heading_along_line=False)
    summary = run_scenario(leg, tmp_path / "leg", plots=False).summary
    assert summary["elastic"]["restarts"] + summary["elastic"]["back_offs"] >= 1
    assert not check_criteria(leg, summary)


@pytest.mark.slow
def test_a_plan_held_at_rest_and_never_made_again_keeps_the_boat_there(tmp_path):
    """Its counter-test (slow: the run goes on to its time limit): with the leg's heading and
    no plan made again (`restart_stuck_s` 0), the boat stays held beside the gap and never
    reaches the goal."""
    scenario = with_options(load_scenario(HELD_BEHIND_A_KAYAK), rest_keep_m=0.0,
                            heading_along_line=False, restart_stuck_s=0.0)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert not summary["reached_goal"], summary["status"]


@pytest.mark.slow  # (2 x 28 s: a whole fuzz case's run, twice; see LONG_RUNS)
def test_a_boat_still_held_at_rest_backs_off_and_comes_on_again(tmp_path):
    """A kayak stopped across half a canal past a side canal, the boat come up to 5 m of it
    following a barge (fuzz seed 1 case 47 as generated on 2026-12-06, known walls). With the
    reference's heading along the line over to the gap the boat goes round without backing
    off, 2 m and more from the kayak. With the leg's heading it stayed at rest, planned
    again from the reference, to the time limit; backing off 8 m along its path, it swings
    round the kayak 2 m off and reaches the goal."""
    scenario = load_scenario(HELD_UNTIL_BACKING_OFF)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert summary["elastic"]["back_offs"] == 0
    assert not check_criteria(scenario, summary)
    leg = with_options(scenario, heading_along_line=False)
    summary = run_scenario(leg, tmp_path / "leg", plots=False).summary
    assert summary["elastic"]["back_offs"] >= 1
    assert not check_criteria(leg, summary)


@pytest.mark.slow
def test_without_backing_off_the_boat_stays_held(tmp_path):
    """The same run with the leg's heading and `back_off_m` 0: held at rest before the kayak
    to the time limit."""
    scenario = with_options(load_scenario(HELD_UNTIL_BACKING_OFF), heading_along_line=False,
                            back_off_m=0.0)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert not summary["reached_goal"], summary["status"]
    assert summary["elastic"]["back_offs"] == 0


KAYAK_AT_REST = REGRESSIONS / "kayak_stopped_in_a_bend_beside_a_barge_followed.toml"


def _kayak_distance(scenario, out):
    summary = run_scenario(scenario, out, plots=False).summary
    assert summary["reached_goal"] and not summary["collision"], summary["status"]
    return next(v for v in summary["vessels"]
                if v["name"] == "drifting-0")["min_hull_distance_m"], summary


@pytest.mark.slow  # (31 s: a whole fuzz case's run; see LONG_RUNS)
def test_a_kayak_at_rest_is_passed_2_m_off_hull_to_hull(tmp_path):
    """A kayak stopped in a bend, passed as the boat follows a barge round it (fuzz seed 1
    case 53, known walls): as a wall like the quay, the slack gave up all of d_p to it and
    the hulls came 1.79 m apart; as a wall grown by `rest_keep_m`, 2 m or more."""
    scenario = load_scenario(KAYAK_AT_REST)
    grown, summary = _kayak_distance(scenario, tmp_path)
    assert grown >= 2.0
    assert not check_criteria(scenario, summary)


@pytest.mark.slow
def test_a_kayak_at_rest_grown_is_passed_farther_than_as_plain_walls(tmp_path):
    """Its counter-test (slow: two runs): grown by `rest_keep_m`, the kayak is passed farther
    by most of the 1.5 m than with its sides walls like any others (`rest_keep_m` 0)."""
    scenario = load_scenario(KAYAK_AT_REST)
    grown, _ = _kayak_distance(scenario, tmp_path)
    plain, _ = _kayak_distance(with_options(scenario, rest_keep_m=0.0), tmp_path / "off")
    assert grown - plain >= 0.75, (grown, plain)


@pytest.mark.slow
def test_vessel_crossing_seed_10_the_soaks_one_failure_reaches_the_goal(tmp_path):
    """The soak's failure at 9bb53ce (`canalnav run scenarios/vessel_crossing.toml --seed
    10`: QP max_iter three steps in a row as the launch crossed, 166 m from the goal)."""
    path = Path(__file__).resolve().parents[2] / "scenarios" / "vessel_crossing.toml"
    scenario = replace(load_scenario(path), seed=10)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert summary["reached_goal"], summary["status"]
    assert not check_criteria(scenario, summary)


@pytest.mark.slow  # (51 s: a whole fuzz case's run; see LONG_RUNS)
def test_a_tour_boat_met_beside_a_barge_keeps_its_track_and_is_passed_clear(tmp_path):
    """Fuzz seed 1 case 77 (LiDAR): a tour boat met head-on round a bend passes 1.75 m from
    a barge the boat follows; their points made one cluster, a track the size of both was
    born on it (11.8 s), the tour boat's id was lost and it was hidden for 10 s: 0.14 m hull
    to hull. Split between the two tracks, the tour boat keeps its track. Then the boat,
    overtaking the barge on its port side (room for the boat, not for the tour boat too)
    with 60 m of sight, was in the tour boat's lane when it came round the bend: a collision
    at 68 s. Now it passes on the barge's starboard side, out of that lane (Rules 9(e), 13),
    and keeps 2 m from every vessel. (The barge's own track changes id where the generated
    7 m boat's route runs through its hull: the fuzz's routes overlap them; and seen from
    its starboard quarter while passed, its part in view makes a track off its centre that
    the tracking figures count false for 21 s. Both are reported, not asserted here.)"""
    scenario = load_scenario(
        REGRESSIONS / "tour_boat_met_round_a_bend_beside_a_barge_followed.toml")
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    tracking = summary["tracking"]
    assert tracking["id_switches"]["meeting-1"] <= 1, tracking
    assert not summary["collision"], summary["status"]
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)


@pytest.mark.slow  # (32 s: the default tests keep the tour boat's split of one cluster)
def test_a_boat_overtaken_close_beside_a_barge_keeps_its_track(tmp_path):
    """Fuzz seed 1 case 84 (LiDAR): a boat the boat overtakes passes a barge 0.45 m off at a
    junction; one cluster for both, its track changed id 9 times and the boat came within
    0.87 m of it. Split between the two tracks, it changes id at most 4 times (how often
    depends on where the boat sees the pair from) and the boat keeps 2 m and more. (Following
    the boat, offset by the barge's starboard pass beyond it, the boat was once squeezed
    past it 0.96 m off: a vessel followed now bounds which passes set the offset.)"""
    scenario = load_scenario(
        REGRESSIONS / "boat_overtaken_close_beside_a_barge_at_a_junction.toml")
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert summary["tracking"]["id_switches"]["overtaken-1"] <= 4, summary["tracking"]
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)


@pytest.mark.slow  # (35 s: a whole fuzz case's run; see LONG_RUNS)
def test_a_vessel_crossing_out_of_a_blind_side_canal_is_given_way_to_in_time(tmp_path):
    """Fuzz seed 1 case 146 (LiDAR): a vessel comes out of a side canal on the starboard
    side and crosses ahead. The reference held the blind-opening speed cap of where the boat
    was over the whole horizon and the boat lagged it, came to the opening at 1.4 m/s and
    passed 0.59 m from the vessel; braking along the horizon it gives way and keeps 2 m."""
    scenario = load_scenario(REGRESSIONS / "vessel_crossing_out_of_a_blind_side_canal.toml")
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    hull = summary["vessels"][0]["min_hull_distance_m"]
    assert hull >= 2.0, hull
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)


@pytest.mark.slow  # (2 x 30 s: a whole fuzz case's run, twice; see LONG_RUNS)
def test_a_boat_out_of_a_blind_side_canal_while_meeting_is_given_way_to(tmp_path):
    """Fuzz seed 1 case 48 (LiDAR): a launch met to port at a side canal's mouth, and a boat
    coming out of the canal unseen. At a blind-opening speed of 0.5 m/s (the file's, opt-in)
    the boat stops in the room it has when it first sees the crossing boat; at 1 m/s (the
    default) it is hit."""
    path = REGRESSIONS / "launch_out_of_a_blind_side_canal_while_meeting.toml"
    scenario = load_scenario(path)
    summary = run_scenario(scenario, tmp_path / "slow", plots=False).summary
    crossing = [v for v in summary["vessels"] if v["name"] == "crossing-1"][0]
    assert crossing["min_hull_distance_m"] >= 2.0, crossing
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)
    fast = run_scenario(with_options(scenario, blind_speed_mps=1.0), tmp_path / "fast",
                        plots=False).summary
    assert [v for v in fast["vessels"] if v["name"] == "crossing-1"][0][
        "min_hull_distance_m"] < 1.0


@pytest.mark.slow  # (2 x 35 s: an encounter's whole run, twice; see LONG_RUNS)
def test_slowed_for_a_blind_opening_the_boat_still_goes_round_a_kayak_stopped_in_its_way(
        tmp_path):
    """The junction encounter (fuzz seed 1 case 24, known walls, its kayak stopped for good
    in the port half at the side canal's mouth) at a blind-opening speed of 0.5 m/s: the
    boat came up behind the kayak at 0.1 m/s and, with the leg's heading across the
    reference's move over to the gap, stayed 10 m short of it to the time limit; with the
    heading along that line it goes round, 2 m and more off, and reaches the goal."""
    scenario = with_options(load_scenario(Path(__file__).parent / "encounters"
                                          / "drifting_kayak_at_a_junction_while_overtaking.toml"),
                            blind_speed_mps=0.5)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)
    leg = with_options(scenario, heading_along_line=False)
    summary = run_scenario(leg, tmp_path / "leg", plots=False).summary
    assert not summary["reached_goal"], summary["status"]


@pytest.mark.slow  # (24 s: a whole fuzz case's run; see LONG_RUNS)
def test_a_kayak_stopped_across_a_bend_is_waited_for_without_going_on(tmp_path):
    """Fuzz seed 1 case 102 (known walls): a kayak stopped across the canal just past a
    bend leaves no way by; the sweep found one through the inner bank, and a boat backing
    off was read 30 m across the canal, so the boat stopped and went on four times, and
    once crept into the bank. It waits now from well before the bend, never goes on, and
    keeps 2 m from the kayak (260 s of the case: its kayak never moves on)."""
    scenario = replace(load_scenario(REGRESSIONS / "kayak_stopped_across_a_bend.toml"),
                       duration_s=260.0)
    result = run_scenario(scenario, tmp_path, plots=False)
    summary = result.summary
    assert not summary["collision"], summary["status"]
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)
    with open(tmp_path / "log.csv") as f:
        rows = [(float(r["time_s"]), r["status"]) for r in csv.DictReader(f)]
    waiting = [t for t, status in rows if status.startswith("waiting")]
    assert waiting and waiting[0] < 150.0, waiting[:1]
    going = [t for t, status in rows if t > waiting[0] and status == "success"]
    assert not going, going[:3]


# Slow since 2026-12-07: with the packages a fresh install took that day (numpy 2.4.6,
# casadi 3.8.2, OpenCV 5.1 or 4.14), this LiDAR case's outcome changed at d1e30d4 itself,
# which passed both on CI the day before; kept out of the default set, still run with
# `-m slow`, until the cause is found (issue 34; the stop's note gives the figures).
@pytest.mark.slow
def test_a_boat_waiting_for_a_kayak_stopped_across_keeps_off_it(tmp_path):
    """Fuzz seed 1 case 3 (LiDAR): a kayak stopped across a narrow canal past a side canal's
    mouth blocks the way; the waiting boat, led about the mouth by the sweep's line into the
    gap beside the kayak, came to 0.98 m of it. Waiting on the rules' line it keeps 2 m."""
    scenario = replace(load_scenario(
        REGRESSIONS / "kayak_stopped_across_a_canal_past_a_side_canal.toml"), duration_s=200.0)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert not summary["collision"], summary["status"]
    kayak = next(v for v in summary["vessels"] if v["name"] == "drifting-0")
    assert kayak["min_hull_distance_m"] >= 2.0, kayak
    assert summary["time_waiting_s"] > 60.0, summary["time_waiting_s"]


def test_a_plan_breaking_its_wall_rows_in_a_gap_is_solved_again(tmp_path):
    """Fuzz seed 1 case 252 (known walls): a kayak stopped before a moored boat in a bend,
    9 m left to the inner bank. The plan broke its wall rows by about 0.5 step after step
    and turned the boat into the bank; solved again from the reference once they have
    broken by more than `restart_broken_h` for a second, it takes the gap and reaches the
    goal."""
    scenario = load_scenario(REGRESSIONS / "kayak_stopped_before_a_moored_boat_in_a_bend.toml")
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert summary["elastic"]["restarts"] >= 1
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)


# Slow since 2026-12-07: with the packages a fresh install took that day (numpy 2.4.6,
# casadi 3.8.2, OpenCV 5.1 or 4.14), this LiDAR case's outcome changed at d1e30d4 itself,
# which passed both on CI the day before; kept out of the default set, still run with
# `-m slow`, until the cause is found (issue 34; the stop's note gives the figures).
@pytest.mark.slow
def test_a_plan_running_past_its_stop_is_solved_again_and_the_boat_waits(tmp_path):
    """Fuzz seed 1 case 90 (LiDAR): a kayak stopped across the canal past a side canal's
    mouth, a current setting the boat towards the mouth. The plan kept its tail through the
    gap beside the kayak, its rows broken by 0.2-0.3 units for 25 s, and drew the boat past
    its stop and into the mouth's far corner at full throttle. Solved again from the
    reference once its rows have broken by 0.15 for a second, the boat stops short and
    waits, 2 m and more from the kayak (150 s of the case: its kayak never moves on)."""
    scenario = replace(load_scenario(
        REGRESSIONS / "kayak_stopped_past_a_side_canal_in_a_cross_current.toml"),
        duration_s=150.0)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert not summary["collision"], summary["status"]
    assert summary["elastic"]["restarts"] >= 1
    assert summary["time_waiting_s"] > 20.0, summary["time_waiting_s"]
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)
    with open(tmp_path / "log.csv") as f:  # stopped short of the kayak (at x = 119 m)
        ahead = max(float(r["true_x_m"]) for r in csv.DictReader(f))
    assert ahead < 114.0, ahead


@pytest.mark.slow  # (2 x 30 s: a whole fuzz case's run, twice; see LONG_RUNS)
def test_a_boat_waiting_in_a_cross_current_stems_it_at_its_stop(tmp_path):
    """Fuzz seed 1 case 69 (known walls): a kayak stopped across the way past a side
    canal's mouth, a 0.36 m/s current across the canal. With the heading weighed in
    proportion to the reference speed below 1 m/s (the file's `heading_full_speed_mps`), the
    boat waits at its stop, bows into the current, 2 m and more from the kayak; with the
    paper's constant weight (the default) it surged to and fro past its stop for the whole
    wait (183 m)."""
    scenario = load_scenario(REGRESSIONS / "boat_waiting_for_a_kayak_in_a_cross_current.toml")
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert not summary["collision"], summary["status"]
    assert summary["time_waiting_s"] > 200.0, summary["time_waiting_s"]
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)
    off = with_options(scenario, heading_full_speed_mps=0.0)
    swung = run_scenario(off, tmp_path / "off", plots=False).summary["swing_while_waiting_m"]
    assert swung > 100.0, swung


@pytest.mark.slow
def test_restarted_only_past_a_unit_the_boat_runs_into_the_bank(tmp_path):
    """The same run restarting only plans that break their rows by more than 1 unit (the
    rule before, `restart_broken_s` 0): a collision with the inner bank."""
    scenario = with_options(load_scenario(
        REGRESSIONS / "kayak_stopped_before_a_moored_boat_in_a_bend.toml"), restart_broken_s=0.0)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert summary["collision"], summary["status"]


def _racing_past_a_kayak(tmp_path, **options):
    """Fuzz seed 1 case 15's first 140 s (the kayak is passed at about 120 s): the summary
    and the boat's highest surge."""
    scenario = with_options(replace(load_scenario(
        REGRESSIONS / "plan_racing_past_a_kayak_wandering_in_a_bend.toml"), duration_s=140.0),
        **options)
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    with open(tmp_path / "log.csv") as f:
        fastest = max(float(r["true_u_mps"]) for r in csv.DictReader(f))
    kayak = next(v for v in summary["vessels"] if v["name"] == "drifting-0")
    return summary, fastest, kayak["min_hull_distance_m"]


@pytest.mark.slow  # (20 s: a whole fuzz case's run; see LONG_RUNS)
def test_a_plan_steering_past_a_kayak_keeps_under_its_surge_ceiling(tmp_path):
    """Fuzz seed 1 case 15 (known walls): steering round a barge followed and a kayak
    wandering in a bend, the plan raced to 3.2 m/s for a target of 2 and passed the kayak
    1.61 m off. Under the soft surge ceiling (0.2 m/s over the reference; not the default
    yet) it keeps to 2.4 m/s and passes it 2 m off or more."""
    summary, fastest, kayak_m = _racing_past_a_kayak(tmp_path, surge_margin_mps=0.2)
    assert not summary["collision"], summary["status"]
    assert fastest <= 2.4, fastest
    assert kayak_m >= 2.0, kayak_m


@pytest.mark.slow
def test_without_the_surge_ceiling_the_plan_races_past_the_kayak(tmp_path):
    """The same run without the ceiling (`surge_margin_mps` None, the default and the
    paper's problem): above 3 m/s, and closer to the kayak than 2 m."""
    summary, fastest, kayak_m = _racing_past_a_kayak(tmp_path)
    assert fastest > 3.0, fastest
    assert kayak_m < 2.0, kayak_m


@pytest.mark.slow  # (30 s: a whole fuzz case's run; see LONG_RUNS)
def test_a_quay_piece_seen_without_its_ends_is_no_vessel(tmp_path):
    """Fuzz seed 1 case 38 (LiDAR): a quay piece near the range kept the speed one glitch gave
    it and became a vessel moving along the quay for 27.6 s. Held at rest along its unseen
    axis, no track sits on a wall for more than a second; the kayak is kept 2 m off. (No
    counter-run: the wall track came with the tuned HPIPM's trajectory, 27.6 s before the
    prior and none after; with casadi's HPIPM, as on CI, the boat goes another way and
    this run had none before either. The mechanism's own test is
    `test_a_track_at_rest_unseen_along_its_axis_loses_the_speed_a_glitch_gave_it`.)"""
    scenario = load_scenario(
        REGRESSIONS / "quay_piece_past_moored_boats_seen_without_its_ends.toml")
    summary = run_scenario(scenario, tmp_path, plots=False).summary
    assert summary["tracking"]["longest_wall_track_s"] <= 1.0, summary["tracking"]
    failed = check_criteria(scenario, summary)
    assert not failed, "; ".join(failed)

