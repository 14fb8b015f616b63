"""`canalnav maneuvers --connect`: the identification runs driven on the simulated autopilot,
in lock-step on a virtual clock: the runs, the logs (CSV from the telemetry, the autopilot's
own .BIN), the fence and the failsafes."""

from __future__ import annotations

import csv
import itertools
from pathlib import Path

import numpy as np
import pytest

from bridge.onboard.loop import EXIT_GOAL, EXIT_STOPPED, BridgeOptions
from bridge.onboard.maneuvers import ManeuverSession, coast_distance_m
from controller.identification.dataflash import read_dataflash
from controller.identification.log_runs import Window, cut_windows, find_runs
from controller.identification.logs import read_log
from controller.identification.maneuvers import SurgeRun, ZigzagRun
from controller.params import IDENTIFIED
from scenarios.scenario_file import parse_scenario

LAKE = """
# open water, 2 km by 600 m, the boat at rest in the middle
[scenario]
name = "lake"
duration_s = 3000
seed = 5

[canal]
centre_line = [[-1000, 0], [1000, 0]]
width_m = 600

[route]
waypoints = [[0, 0], [900, 0]]

[initial]
x_m = 0.0
y_m = 0.0
psi_deg = 0.0
u_mps = 0.0

[origin]
lat_deg = 52.0
lon_deg = 4.0
"""


@pytest.fixture(scope="module")
def lake():
    return parse_scenario(LAKE, "lake.toml")


@pytest.fixture
def boat(lake, sim_rig, tmp_path):
    """Factory: the simulated autopilot (DataFlash log on) <- (relay) -> a link on a virtual
    clock at 50 Hz, the autopilot's logging rate for RCOU (tests/bridge/rigs.py)."""
    made = itertools.count()

    def make(seed=1, relay=False, tick_s=0.02):
        return sim_rig(lake, seed=seed, relay=relay, tick_s=tick_s, ekf_delay_s=5.0, init_s=2.0,
                       log_dir=tmp_path / f"logs{next(made)}", physics_step_s=tick_s,
                       link_kwargs={"geodetic_origin": lake.geodetic_origin})

    return make


def start_session(b, scenario, runs, out, **kwargs):
    """A manoeuvre session on the rig's link, MANUAL and armed, its console the rig's."""
    return ManeuverSession(b.link, scenario, runs,
                           BridgeOptions(mode="MANUAL", arm=True, ekf_timeout_s=30.0), out,
                           console=b.console, **kwargs)


@pytest.mark.slow  # about 35 s: two sessions of manoeuvres on the simulated autopilot
def test_a_staircase_and_a_zigzag_logged_twice_the_same(boat, lake, tmp_path):
    """Both logs say the same: the CSV from the telemetry and the autopilot's own .BIN over
    the window the session printed; the commands moved no faster than the actuators."""
    b = boat()
    runs = (SurgeRun("01_acceleration", "acceleration", (31.0, 50.6), lead_in_s=3.0),
            ZigzagRun("02_zigzag_20_50", 20.0, 50.0, 42.0, overshoots=2))
    result = start_session(b, lake, runs, tmp_path / "out", hold_s=12.0).run()
    assert result.exit_code == EXIT_GOAL and result.reason == "manoeuvres done", result
    acc, zig = (read_log(p) for p in result.paths)
    assert acc.meta["maneuver"] == "acceleration" and zig.meta["maneuver"] == "zigzag"
    assert acc.commands[0, 0] == 0 and acc.commands[-1, 0] == pytest.approx(50.6, abs=0.5)
    for log, k, rate in ((acc, 0, 10.0), (zig, 1, 40.0)):  # %/s; a step of 0.1 s at most
        step = np.abs(np.diff(log.commands[:, k]))
        assert np.all(step <= rate * np.diff(log.time_s) + rate * 0.1 + 0.3), step.max()
    assert np.abs(zig.commands[:, 1]).max() == pytest.approx(50.0, abs=0.3)
    psi = np.degrees(np.unwrap(zig.states[:, 2]))
    assert np.ptp(psi) > 40  # +-20 deg and the overshoots
    console = b.console.getvalue()
    assert "sysid LOG.BIN --window" in console and "manoeuvres done: neutral sent" in console
    # the autopilot's own log, over the same windows
    (bin_path,) = b.autopilot.log_paths
    flight = read_dataflash(bin_path)
    windows = [Window.parse(log.meta["window"]) for log in (acc, zig)]
    for csv_log, cut in zip((acc, zig), cut_windows(flight, windows)):
        t = cut.time_s
        for k in range(6):
            ours = np.interp(t, csv_log.time_s, csv_log.states[:, k] if k != 2 else
                             np.unwrap(csv_log.states[:, k]))
            theirs = cut.states[:, k] if k != 2 else np.unwrap(cut.states[:, k])
            assert np.abs(ours - theirs)[5:-5].max() < [0.15, 0.15, 0.01, 0.05, 0.05, 0.01][k]
        nT = np.interp(t, csv_log.time_s, csv_log.commands[:, 0])
        assert np.abs(nT - cut.commands[:, 0])[5:-5].max() <= 1.2  # one step of the ramp
    kinds = [r.meta["maneuver"] for r in find_runs(flight)]
    assert "zigzag" in kinds and kinds[0] == "acceleration", kinds
    with (tmp_path / "out" / "session.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert rows[-1]["event"] == "manoeuvres done" and any(r["run"] == "02_zigzag_20_50" for r in rows)


def test_a_run_that_would_leave_the_radius_is_cut_short(boat, lake, tmp_path):
    b = boat()
    runs = (SurgeRun("01_acceleration", "acceleration", (50.6,), lead_in_s=2.0),)
    result = start_session(b, lake, runs, tmp_path / "out", hold_s=60.0, radius_m=60.0).run()
    assert result.exit_code == EXIT_GOAL
    (record,) = result.runs
    assert record.cut_short.startswith("coasting from") and "leave the radius" in record.cut_short
    log = read_log(result.paths[0])
    assert "cut_short" in log.meta and log.time_s[-1] - log.time_s[0] < 60.0
    # the fence left room to stop: the boat never went beyond the radius
    xy = np.array(b.autopilot.true_state[:2])
    assert np.hypot(*xy) < 60.0
    assert b.autopilot.true_state[3] < 0.4  # slowed down before the session ended
    assert f"01_acceleration cut short: {record.cut_short}" in b.console.getvalue()


def test_the_link_lost_mid_run_fails_safe(boat, lake, tmp_path):
    b = boat(relay=True)
    runs = (SurgeRun("01_acceleration", "acceleration", (31.0, 41.0), lead_in_s=2.0),)
    session = start_session(b, lake, runs, tmp_path / "out", hold_s=20.0)
    cut = []

    def script(now):  # 3 s into the run
        rec = session._recording
        if not cut and rec is not None and len(rec.rows) > 30:
            cut.append(now)
            b.relay.cut(now, now + 10.0)

    b.clock.add_peer(script)
    result = session.run()
    assert result.exit_code == EXIT_STOPPED and result.reason.startswith("state stale"), result
    assert result.failsafes == [result.reason]
    assert "FAILSAFE state stale" in b.console.getvalue()
    assert result.paths and read_log(result.paths[0]).n_samples > 10  # kept what it had
    b.clock.sleep(4.0)  # RC_OVERRIDE_TIME: the autopilot stops obeying the last command
    assert b.autopilot.outputs == (0.0, 0.0)


def test_a_loop_behind_the_clock_keeps_the_manoeuvre_timing_and_says_so(boat, lake, tmp_path):
    """Each control step made 0.3 s late (a busy computer, a sped-up clock): the steering
    still ramps at the actuator's 40 %/s of clock time (not 4 % per late step), and the late
    steps are counted and reported."""
    b = boat()
    runs = (ZigzagRun("01_zigzag_20_50", 20.0, 50.0, 42.0, overshoots=1),)
    session = start_session(b, lake, runs, tmp_path / "out", hold_s=2.0)
    send = b.link.send_commands

    def slow_send(*cmd):
        send(*cmd)
        b.clock.sleep(0.3)  # the autopilot runs on meanwhile

    b.link.send_commands = slow_send
    result = session.run()
    assert result.exit_code == EXIT_GOAL, result
    zig = read_log(result.paths[0])
    t, nS = zig.time_s, np.abs(zig.commands[:, 1])
    ramp_s = t[np.argmax(nS >= 49.0)] - t[np.argmax(nS > 1.0)]
    assert ramp_s < 2.5, ramp_s  # 50 % at 40 %/s: 1.25 s and a late step (5 s before)
    assert result.late_steps > 0.9 * result.steps and 0.15 < result.worst_late_s < 0.5
    console = b.console.getvalue()
    assert "control loop falls behind the clock" in console
    assert f"{result.late_steps} of {result.steps} steps late" in console


def test_coasting_distance_from_the_surge_equation():
    d = coast_distance_m(IDENTIFIED, 2.25, 0.2)
    assert 40.0 < d < 55.0  # the paper's boat coasts about 48 m from its top test speed
    assert coast_distance_m(IDENTIFIED, 0.1) == 0.0


def test_in_short_water_each_level_is_held_shorter_and_said(boat, lake, tmp_path):
    """Two levels of 60 s need about 250 m; within a 150 m radius the session holds each
    shorter (not less than 20 s) so that the run ends in the water, not cut short."""
    b = boat()
    runs = (SurgeRun("01_acceleration", "acceleration", (31.0, 50.6), lead_in_s=2.0),)
    result = start_session(b, lake, runs, tmp_path / "out", hold_s=60.0, radius_m=150.0).run()
    assert result.exit_code == EXIT_GOAL, result
    console = b.console.getvalue()
    assert "the runs need about 01_acceleration" in console
    held = float(console.split("01_acceleration: each level held ")[1].split(" s")[0])
    assert 20.0 <= held < 60.0
    (record,) = result.runs
    assert not record.cut_short, record.cut_short
    log = read_log(result.paths[0])
    assert log.time_s[-1] - log.time_s[0] == pytest.approx(2.0 + 2 * held, abs=1.5)
    assert np.hypot(*np.array(b.autopilot.true_state[:2])) < 150.0
