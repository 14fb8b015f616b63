"""The closed loop with the Python-model plant and the LOS-PID tracker on a straight canal."""

import json

import numpy as np
import pytest

from controller.params import IDENTIFIED
from scenarios.loop.closed_loop import Decision, LoopConfig, run_closed_loop
from scenarios.loop.controllers import LosPidController
from scenarios.plants.plant import ModelPlant

WALLS = (np.array([[-10.0, -8.0], [300.0, -8.0]]), np.array([[-10.0, 8.0], [300.0, 8.0]]))
WAYPOINTS = np.array([[0.0, 0.0], [100.0, 0.0], [200.0, 2.0]])


class NoPerception:
    def segments(self, t, true_state, est_state):
        return np.empty((0, 4))


def run(tmp_path, seed=1, controller=None, duration=200.0, **sensors):
    cfg = LoopConfig(duration_s=duration, waypoints=WAYPOINTS, outlines=WALLS,
                     desired_separation_m=5.0, seed=seed, snapshot_times_s=(10.0,), **sensors)
    ctrl = controller or LosPidController(IDENTIFIED, WAYPOINTS)
    return run_closed_loop(ModelPlant(IDENTIFIED), ctrl, NoPerception(), [0, 1.0, 0, 0, 0, 0],
                           cfg, tmp_path, scenario_name="straight")


def test_reaches_the_goal_and_reports_metrics(tmp_path):
    result = run(tmp_path / "a")
    s = result.summary
    assert s["reached_goal"] and s["status"] == "reached goal"
    assert s["controller"] == "los-pid" and s["seed"] == 1
    assert 5.8 < s["min_clearance_m"] <= 7.0  # 8 m walls; start 1 m off, last waypoint 2 m off
    assert s["mean_cross_track_m"] < 0.5
    assert s["control_effort_Jc"] > 0
    assert 90 < s["duration_s"] < 130  # ~200 m at 2 m/s after the start
    t = result.timing
    assert t["solve_ms"]["max"] >= t["solve_ms"]["mean"] > 0
    assert set(t["where_the_time_goes_s"]) >= {"plant", "navigation", "controller", "perception"}
    assert len(result.snapshots) == 1


def test_log_is_complete_and_flushed(tmp_path):
    result = run(tmp_path / "a")
    lines = result.log_path.read_text().splitlines()
    assert lines[0].startswith("time_s,true_x_m")
    assert len(lines) - 1 == result.summary["steps"]
    last = lines[-1].split(",")
    assert float(last[0]) == pytest.approx(result.summary["duration_s"] - 0.1)


def test_same_seed_gives_byte_identical_summary(tmp_path):
    run(tmp_path / "a", seed=4)
    run(tmp_path / "b", seed=4)
    a = (tmp_path / "a" / "summary.json").read_bytes()
    assert a == (tmp_path / "b" / "summary.json").read_bytes()
    run(tmp_path / "c", seed=5)
    assert a != (tmp_path / "c" / "summary.json").read_bytes()


def test_controller_failure_stops_the_boat_and_ends_the_run(tmp_path):
    class Failing:
        name = "failing"

        def step(self, t, state, act, segs):
            if t >= 5.0:
                return Decision(command=np.array([80.0, 0.0]), ok=False, status="QP infeasible")
            return Decision(command=np.array([40.0, 0.0]))

    result = run(tmp_path / "f", controller=Failing())
    s = result.summary
    assert not s["reached_goal"] and s["status"] == "controller failed: QP infeasible"
    last = result.log_path.read_text().splitlines()[-1].split(",")
    assert float(last[13]) == 0.0 and float(last[14]) == 0.0  # neutral commands sent
    assert json.loads((tmp_path / "f" / "summary.json").read_text())["steps"] == 51


def test_touching_a_wall_ends_the_run_as_a_collision(tmp_path):
    class HardToStarboard:
        name = "starboard"

        def step(self, t, state, act, segs):
            return Decision(command=np.array([60.0, -60.0]))

    s = run(tmp_path / "c", controller=HardToStarboard()).summary
    assert s["collision"] and s["status"].startswith("collision at t = ") and not s["reached_goal"]
    assert s["min_clearance_m"] < 3.0
    assert not run(tmp_path / "ok").summary["collision"]


def test_plots_are_written_from_the_run_directory(tmp_path):
    from scenarios.results import plots

    d = tmp_path / "p"
    run(d, duration=20.0)
    outs = [
        plots.plot_trajectory(d, WALLS, WAYPOINTS, d / "trajectory.png"),
        plots.plot_separation({"los-pid": d}, 5.0, d / "separation.png"),
        plots.plot_states(d, d / "states.png"),
    ]
    for out in outs:
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000


def test_the_gps_settings_reach_the_filter(tmp_path):
    """A 1 Hz fix with 1 m noise leaves the estimate metres off; the RTK default, centimetres."""
    from scenarios.results.plots import read_log
    from scenarios.sensors.gps_ahrs import GpsConfig

    def position_error(folder, **sensors):
        run(folder, duration=60.0, **sensors)
        log = read_log(folder / "log.csv")
        error = np.hypot(log["est_x_m"] - log["true_x_m"], log["est_y_m"] - log["true_y_m"])
        return float(error[100:].mean())

    rtk = position_error(tmp_path / "rtk")
    poor = position_error(tmp_path / "poor", gps=GpsConfig(rate_hz=1.0, pos_sigma_m=1.0,
                                                           vel_sigma_mps=0.3))
    assert rtk < 0.05 and poor > 0.2


def test_the_canal_width_is_logged_and_summarised(tmp_path):
    """16 m between the walls everywhere: never narrower than 2 x 5 m, so no narrow time, and
    the clearance where wide is the run's minimum."""
    from scenarios.results.plots import read_log

    result = run(tmp_path / "a")
    log = read_log(result.log_path)
    assert np.allclose(log["canal_width_m"], 16.0)
    assert np.allclose(log["canal_width_min_hull_m"], 16.0)
    assert np.allclose(log["centre_offset_m"], log["true_y_m"], atol=1e-6)  # + to starboard (east)
    s = result.summary
    assert s["narrow_below_m"] == 10.0 and s["time_narrow_s"] == 0.0
    assert s["min_clearance_where_wide_m"] == s["min_clearance_m"]
    assert s["mean_centre_offset_narrow_m"] is None


def test_the_goal_is_reached_past_its_finish_line_only_on_the_last_leg():
    """As ArduPilot counts a waypoint passed: within the goal radius, or past the line square
    to the last leg through the goal (a boat kept 7 m to one side by another vessel); never
    where an earlier leg of a route that doubles back lies behind that line."""
    from scenarios.loop.closed_loop import _finish_direction, _past_finish

    finish = _finish_direction(WAYPOINTS)
    assert _past_finish(np.array([200.5, 9.0]), WAYPOINTS, finish)
    assert not _past_finish(np.array([199.0, 9.0]), WAYPOINTS, finish)
    back = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 40.0], [50.0, 40.0]])
    turn = _finish_direction(back)
    assert _past_finish(np.array([45.0, 38.0]), back, turn)
    assert not _past_finish(np.array([20.0, 1.0]), back, turn)  # on the first leg
