"""The onboard loop against the scripted fake autopilot, in lock-step: goal, refusals, failsafes.

Each failsafe must reach the autopilot as neutral commands, then released overrides, then
HOLD (only when the bridge controls the mode), then a STATUSTEXT saying why, in that order.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bridge.shared.ardupilot import MODES
from bridge.onboard.link import AutopilotLink, LinkError
from bridge.main import main
from bridge.onboard.loop import (EXIT_GOAL, EXIT_INTERRUPTED, EXIT_REFUSED, EXIT_STOPPED,
                            BridgeOptions, OnboardLoop, nearest_segment_m, prepare_link)
from bridge.onboard.step_log import STEP_COLUMNS, StepLog
from scenarios.loop.closed_loop import Decision
from scenarios.scenario_file import load_scenario

from pymavlink import mavutil

ROOT = Path(__file__).resolve().parents[2]
STRAIGHT = ROOT / "scenarios" / "straight.toml"
HOLD = MODES["HOLD"]


@pytest.fixture(scope="module")
def scenario():
    s = load_scenario(STRAIGHT)
    return replace(s, waypoints=np.array([[0.0, 0.0], [30.0, 0.0]]))


class StubController:
    """Constant commands; fails, interrupts or raises at a given call when told to."""

    name = "stub"

    def __init__(self, command=(30.0, 10.0), fail_at=None, interrupt_at=None, raise_at=None):
        self.command = command
        self.fail_at, self.interrupt_at, self.raise_at = fail_at, interrupt_at, raise_at
        self.calls = []
        self.resets = 0

    def step(self, time_s, state, actuators, segments):
        self.calls.append((time_s, np.array(state), np.array(actuators), len(segments)))
        k = len(self.calls)
        if k == self.interrupt_at:
            raise KeyboardInterrupt
        if k == self.raise_at:
            raise RuntimeError("boom")
        if k == self.fail_at:
            return Decision(command=np.zeros(2), ok=False, status="QP infeasible")
        return Decision(command=np.array(self.command, float))

    def reset(self):
        self.resets += 1


class NoLidar:
    def scan(self, time_s, pose):
        return None


OPTIONS = BridgeOptions(heartbeat_timeout_s=5.0, ekf_timeout_s=5.0,
                        origin=(52.0, 4.0, 0.0))  # the fake autopilot's (straight.toml has none)


def run_loop(ap, clock, scenario, controller, log_dir=None, lidar=None, at=None, viz=None,
             **options):
    """Run the loop; `at` = {time_s: action(ap)} applied by a clock peer."""
    link_kwargs = {k: options.pop(k) for k in ("link_timeout_s", "stale_s") if k in options}
    pending = dict(sorted((at or {}).items()))

    def script(now):
        for t in [t for t in pending if now >= t]:
            pending.pop(t)(ap)

    clock.add_peer(script)
    link = AutopilotLink(ap.url, clock, tlog_path=None if log_dir is None else log_dir / "mavlink.tlog",
                         **link_kwargs)
    console = io.StringIO()
    log = StepLog(log_dir, viz)
    loop = OnboardLoop(link, scenario, controller, lidar or NoLidar(), replace(OPTIONS, **options),
                       console=console, log=log)
    try:
        result = loop.run()
    finally:
        log.close()
        link.close()
        clock.sleep(0.05)  # the autopilot reads what was sent last
    return result, console.getvalue()


def events(ap, since=0.0):
    """What the autopilot received from `since` on, as a compressed list of safety events."""
    out = []
    for t, msg in ap.received:
        if t < since:
            continue
        kind = msg.get_type()
        if kind == "RC_CHANNELS_OVERRIDE":
            ch = [getattr(msg, f"chan{i}_raw") for i in range(1, 9)]
            e = "release" if ch == [0] * 8 else "neutral" if (ch[0], ch[2]) == (1500, 1500) else "drive"
        elif kind == "COMMAND_LONG" and msg.command == mavutil.mavlink.MAV_CMD_DO_SET_MODE:
            e = f"mode {int(msg.param2)}"
        elif kind == "COMMAND_LONG" and msg.command == mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            e = "arm"
        elif kind == "STATUSTEXT":
            if msg.chunk_seq > 0 and out and out[-1].startswith("text: "):
                out[-1] += msg.text  # a long text comes in chunks
                continue
            e = f"text: {msg.text}"
        else:
            continue
        if not out or out[-1] != e:
            out.append(e)
    return out


def read_steps(log_dir):
    with open(log_dir / "steps.csv") as fh:
        return list(csv.DictReader(fh))


def test_runs_to_the_goal_and_exits_0(make_autopilot, vclock, scenario, tmp_path):
    ap = make_autopilot(state=(0.0, 1.0, 0.0, 4.0, 0.0, 0.0))
    ctrl = StubController(command=(30.0, 10.0))
    result, console = run_loop(ap, vclock, scenario, ctrl, log_dir=tmp_path)
    assert result.exit_code == EXIT_GOAL and result.reached_goal and result.reason == "reached the goal"
    # from where the loop started to 25 m (the goal's radius short of it) at 4 m/s, 10 Hz
    rows = read_steps(tmp_path)
    x0 = float(next(r for r in rows if r["x_m"])["x_m"])
    assert result.steps == pytest.approx((25.0 - x0) / 0.4, abs=3)
    # commands at the autopilot: nT 30 on ch3 above trim, nS 10 (port) on ch1 below trim
    drive = [o for o in ap.overrides() if o[2] not in (0, 1500)]
    assert drive[0][:8] == [1433, 65535, 1641, 65535, 65535, 65535, 65535, 65535]
    assert len(drive) == result.steps
    # never arms or changes mode unless asked; the end: neutral, release, then the word
    assert events(ap) == ["drive", "neutral", "release", "text: canalnav: reached the goal"]
    # the controller sees the state predicted over age + delay: ahead of the reported one
    t, state, actuators, _ = ctrl.calls[5]
    assert actuators.tolist() == [30.0, 10.0] and ctrl.calls[0][2].tolist() == [0.0, 0.0]
    rows = read_steps(tmp_path)
    steps = [r for r in rows if r["x_m"]]
    assert len(steps) == result.steps and list(rows[0]) == list(STEP_COLUMNS)
    r = steps[5]
    assert float(r["pred_x_m"]) > float(r["x_m"])
    dt = float(r["state_age_s"]) + float(r["link_delay_s"])
    assert float(r["pred_x_m"]) - float(r["x_m"]) == pytest.approx(4.0 * dt, abs=1e-6)
    assert (int(r["throttle_pwm_us"]), int(r["steering_pwm_us"])) == (1641, 1433)
    assert r["mode"] == "MANUAL" and r["armed"] == "0" and 0 < float(r["link_delay_s"]) < 0.05
    assert rows[-1]["status"] == "reached the goal"
    assert (tmp_path / "mavlink.tlog").stat().st_size > 1000
    assert "autopilot: system 1 component 1, boat, MANUAL, disarmed" in console
    assert "note: the autopilot is disarmed and --arm was not given" in console


def test_mode_and_arm_when_asked_and_hold_at_the_goal(make_autopilot, vclock, scenario):
    ap = make_autopilot(mode="HOLD", armed=False, state=(0.0, 0.0, 0.0, 5.0, 0.0, 0.0))
    result, console = run_loop(ap, vclock, scenario, StubController(), mode="MANUAL", arm=True)
    assert result.exit_code == EXIT_GOAL
    ev = events(ap)
    assert ev[:3] == [f"mode {MODES['MANUAL']}", "arm", "drive"]
    assert ev[3:] == ["neutral", "release", f"mode {HOLD}", "text: canalnav: reached the goal"]
    assert ap.mode_name == "HOLD" and ap.armed
    assert "mode set to MANUAL" in console and "armed" in console


def test_preflight_refusal_exits_3_and_sends_nothing(make_autopilot, vclock, scenario):
    ap = make_autopilot(params={"RC_OPTIONS": 2, "MAV_GCS_SYSID": 250}, mode="HOLD")
    ctrl = StubController()
    result, console = run_loop(ap, vclock, scenario, ctrl, arm=True)
    assert result.exit_code == EXIT_REFUSED and not ctrl.calls
    assert "RC_OPTIONS = 2 has bit 1" in console and "MAV_GCS_SYSID = 250" in console
    assert "HEARTBEAT.custom_mode = 4 (HOLD)" in console
    assert ap.overrides() == [] and events(ap) == []  # no arming, no overrides


FAILSAFES = {
    # name: (controller, script, loop options, expected reason start, exit code)
    "link lost": (dict(), {1.0: lambda ap: setattr(ap, "mute", True)},
                  dict(link_timeout_s=0.5), "link lost (", EXIT_STOPPED),
    "state stale": (dict(), {1.0: lambda ap: setattr(ap, "send_state", False)},
                    dict(), "state stale (", EXIT_STOPPED),
    "controller failure": (dict(fail_at=10), {}, dict(), "controller failed: QP infeasible",
                           EXIT_STOPPED),
    "ctrl-c": (dict(interrupt_at=10), {}, dict(), "interrupted (Ctrl-C)", EXIT_INTERRUPTED),
    "ekf position lost": (dict(), {1.0: lambda ap: setattr(ap, "ekf_flags", 1 | 2 | 512)}, dict(),
                          "EKF position unusable (flags 0x203)", EXIT_STOPPED),
}


@pytest.mark.parametrize("name", list(FAILSAFES))
@pytest.mark.parametrize("mode", [None, "MANUAL"])
def test_failsafe_neutral_release_hold_statustext_in_order(make_autopilot, vclock, scenario,
                                                           tmp_path, name, mode):
    ctrl_kwargs, script, opts, reason, code = FAILSAFES[name]
    ap = make_autopilot(state=(0.0, 0.0, 0.0, 1.0, 0.0, 0.0))
    result, console = run_loop(ap, vclock, scenario, StubController(**ctrl_kwargs), log_dir=tmp_path,
                               at=script, mode=mode, **opts)
    assert result.exit_code == code and result.reason.startswith(reason)
    assert result.failsafes == [result.reason]
    hold = [f"mode {HOLD}"] if mode else []
    ev = events(ap)
    assert ev[ev.index("drive"):] == ["drive", "neutral", "release", *hold,
                                      f"text: canalnav: FAILSAFE {result.reason}"]
    assert f"bridge: FAILSAFE {result.reason}: neutral sent, overrides released" in console
    if mode and name == "link lost":
        assert "HOLD failed (no answer to mode HOLD" in console  # sent, but no ACK came back
    rows = read_steps(tmp_path)
    assert rows[-1]["status"] == f"FAILSAFE {result.reason}"
    assert len([r for r in rows if r["x_m"]]) == result.steps >= 5


def test_error_inside_the_loop_fails_safe_then_raises(make_autopilot, vclock, scenario):
    ap = make_autopilot()
    with pytest.raises(RuntimeError, match="boom"):
        run_loop(ap, vclock, scenario, StubController(raise_at=3))
    assert events(ap) == ["drive", "neutral", "release", "text: canalnav: FAILSAFE bridge error: boom"]


def test_time_limit(make_autopilot, vclock, scenario):
    ap = make_autopilot(state=(0.0, 0.0, 0.0, 0.5, 0.0, 0.0))
    result, _ = run_loop(ap, vclock, scenario, StubController(), duration_s=2.0)
    assert result.exit_code == EXIT_STOPPED and result.reason == "time limit"
    assert result.steps == 20
    assert events(ap)[-3:] == ["neutral", "release", "text: canalnav: time limit"]


def test_resume_after_the_link_comes_back(make_autopilot, vclock, scenario, tmp_path):
    ap = make_autopilot(state=(0.0, 0.0, 0.0, 2.0, 0.0, 0.0))
    ctrl = StubController()
    cut = {1.0: lambda ap: setattr(ap, "mute", True), 5.0: lambda ap: setattr(ap, "mute", False)}
    result, console = run_loop(ap, vclock, scenario, ctrl, log_dir=tmp_path, at=cut, mode="MANUAL",
                               resume=True)
    assert result.exit_code == EXIT_GOAL
    assert len(result.failsafes) == 1 and result.failsafes[0].startswith("state stale")
    assert ctrl.resets == 1
    ev = events(ap)
    i = ev.index("release")
    assert ev[i - 2:i + 5] == ["drive", "neutral", "release", f"mode {HOLD}",
                               f"text: canalnav: FAILSAFE {result.failsafes[0]}",
                               f"mode {MODES['MANUAL']}", "text: canalnav: resumed control"]
    assert ev[i + 5] == "drive"
    assert "waiting for the link and the EKF state to come back (--resume)" in console
    assert "bridge: resumed" in console
    statuses = [r["status"] for r in read_steps(tmp_path) if not r["x_m"]]
    assert statuses == [f"FAILSAFE {result.failsafes[0]}", "resumed", "reached the goal"]


def test_resume_after_an_autopilot_restart(make_autopilot, vclock, scenario):
    ap = make_autopilot(state=(0.0, 0.0, 0.0, 2.0, 0.0, 0.0))

    def reboot(ap):
        ap.restart()  # forgets the message rates: the state goes stale until re-requested
        ap.armed = False

    result, _ = run_loop(ap, vclock, scenario, StubController(), at={3.0: reboot}, arm=True,
                         resume=True)
    assert result.exit_code == EXIT_GOAL and len(result.failsafes) == 1
    assert events(ap).count("arm") == 2  # armed again, as asked at the start
    assert len([m for m in ap.messages("COMMAND_LONG") if m.command == 511]) == 8  # rates twice


def test_resume_after_a_controller_failure(make_autopilot, vclock, scenario):
    ap = make_autopilot(state=(0.0, 0.0, 0.0, 4.0, 0.0, 0.0))
    ctrl = StubController(fail_at=10)
    result, _ = run_loop(ap, vclock, scenario, ctrl, mode="MANUAL", resume=True)
    assert result.exit_code == EXIT_GOAL
    assert result.failsafes == ["controller failed: QP infeasible"] and ctrl.resets == 1
    ev = events(ap)
    assert ev[:9] == [f"mode {MODES['MANUAL']}", "drive", "neutral", "release", f"mode {HOLD}",
                      "text: canalnav: FAILSAFE controller failed: QP infeasible",
                      f"mode {MODES['MANUAL']}", "text: canalnav: resumed control", "drive"]


def test_no_resume_without_the_option_even_if_the_link_returns(make_autopilot, vclock, scenario):
    ap = make_autopilot()
    cut = {1.0: lambda ap: setattr(ap, "mute", True), 3.0: lambda ap: setattr(ap, "mute", False)}
    result, _ = run_loop(ap, vclock, scenario, StubController(), at=cut)
    assert result.exit_code == EXIT_STOPPED and "drive" not in events(ap)[-3:]


def test_waits_for_the_ekf_then_drives(make_autopilot, vclock, scenario):
    ap = make_autopilot(ekf_flags=1 | 2 | 512)  # predicted position only
    result, _ = run_loop(ap, vclock, scenario, StubController(), duration_s=0.5,
                         at={3.0: lambda ap: setattr(ap, "ekf_flags", 1 | 2 | 16)})
    assert result.exit_code == EXIT_STOPPED and result.steps == 5
    first_drive = next(t for t, m in ap.received if m.get_type() == "RC_CHANNELS_OVERRIDE")
    assert first_drive >= 3.0


def test_ekf_timeout_is_a_link_error(make_autopilot, vclock, scenario):
    ap = make_autopilot(ekf_flags=0)
    with pytest.raises(LinkError, match=r"no usable horizontal position from the EKF within 5 s "
                                        r"\(EKF_STATUS_REPORT flags: 0x0000"):
        run_loop(ap, vclock, scenario, StubController())
    assert ap.overrides() == []


def test_prepare_link_for_a_plant(make_autopilot, vclock, scenario):
    """The MAVLink plant reuses prepare_link on its own link."""
    ap = make_autopilot(params={"RCMAP_ROLL": 2, "RCMAP_THROTTLE": 4, "MAV_GCS_SYSID": 200})
    link = AutopilotLink(ap.url, vclock, system_id=200)
    prep = prepare_link(link, scenario, replace(OPTIONS, system_id=200))
    assert (link.rc_mapping.steering.channel, link.rc_mapping.throttle.channel) == (2, 4)
    assert prep.params["SYSID_MYGCS"] == 200 and prep.streams["ATTITUDE"] == 0
    assert link.state is not None and link.horizontal_position_ok
    link.close()


def test_real_nmpc_and_simulated_lidar_for_a_few_steps(make_autopilot, vclock, tmp_path):
    from bridge.lidar import SimLidarSource
    from scenarios.loop.controllers import NmpcController

    scenario = load_scenario(STRAIGHT)
    ap = make_autopilot(state=tuple(scenario.initial_state))
    result, console = run_loop(ap, vclock, scenario, NmpcController(scenario), log_dir=tmp_path,
                               lidar=SimLidarSource(scenario), duration_s=1.0)
    assert result.exit_code == EXIT_STOPPED and result.steps == 10
    rows = [r for r in read_steps(tmp_path) if r["x_m"]]
    assert all(int(r["segments"]) >= 2 for r in rows)  # both canal walls
    # the canal is 20 m wide around y = 0 and the boat starts at y = 2: the wall is 8 m away
    assert all(float(r["nearest_segment_m"]) == pytest.approx(8.0, abs=0.3) for r in rows)
    nT = [float(r["nT_cmd_pct"]) for r in rows]
    assert all(math.isfinite(v) for v in nT) and nT[-1] > 0
    # a status line every 50 steps when the console is not a terminal
    assert re.search(r"t +0\.0 s  MANUAL +disarmed x +0\.\d y +2\.0 hdg +0\.0 .* wall +8\.0 m", console)


def test_nearest_segment():
    segs = np.array([[0.0, 10.0, 0.0, 20.0], [50.0, -3.0, math.pi / 2, 2.0]])
    assert nearest_segment_m((0.0, 0.0), segs) == pytest.approx(10.0)
    assert nearest_segment_m((50.0, 0.0), segs) == pytest.approx(2.0)
    assert nearest_segment_m((0.0, 0.0), np.zeros((0, 4))) == math.inf


def test_cli_bad_input_is_one_clear_line(capsys, tmp_path):
    assert main(["bridge", "--scenario", str(STRAIGHT), "--connect", "udpout:127.0.0.1:9"]) == 2
    err = capsys.readouterr().err
    assert "no geodetic origin: the scenario" in err and "[origin] lat_deg" in err
    assert "--origin=-35.363261,149.16523,584" in err and len(err.strip().splitlines()) == 1
    for bad in ("52", "52,x", "91,4", "52,4,0,1"):
        assert main(["bridge", "--scenario", str(STRAIGHT), "--connect", "udpout:127.0.0.1:9",
                     "--origin", bad]) == 2
        assert f"--origin {bad!r}" in capsys.readouterr().err
    base = ["bridge", "--scenario", str(STRAIGHT), "--origin", "52.0,4.0"]
    assert main(base + ["--connect", "udpin:nonsense"]) == 2
    assert "cannot open the MAVLink connection 'udpin:nonsense'" in capsys.readouterr().err
    assert main(base + ["--connect", "udpout:127.0.0.1:9", "--signing-key",
                        str(tmp_path / "none.key")]) == 2
    assert "no such signing key file" in capsys.readouterr().err
    assert main(base + ["--connect", "udpout:127.0.0.1:9", "--lidar", "camera"]) == 2
    assert "expected 'sim', 'replay:DIR', 'velodyne:PORT'" in capsys.readouterr().err
    assert main(base + ["--connect", "udpout:127.0.0.1:9", "--mode", "FLY"]) == 2
    assert "--mode FLY: not a Rover mode" in capsys.readouterr().err
    assert main(base + ["--connect", "udpout:127.0.0.1:9", "--duration", "-1"]) == 2
    assert "--duration must be a positive number" in capsys.readouterr().err
    assert main(["bridge", "--connect", "udpout:127.0.0.1:9", "--scenario", "nope.toml",
                 "--origin", "52,4"]) == 2
    assert "no such scenario file" in capsys.readouterr().err


def test_frames_that_disagree_are_refused_and_a_missing_origin_is_a_note(make_autopilot, vclock,
                                                                        scenario):
    from controller.geodetic import ned_to_geodetic

    ap = make_autopilot()
    lat, lon = ned_to_geodetic(10.0, 0.0, ap.origin)
    ap.ekf_origin = (lat, lon, 0.0)  # GPS_GLOBAL_ORIGIN 10 m off the local frame's zero
    result, console = run_loop(ap, vclock, scenario, StubController())
    assert result.exit_code == EXIT_REFUSED
    assert re.search(r"LOCAL_POSITION_NED from the EKF origin .* 10\.\d m apart; the "
                     r"autopilot's frames disagree", console), console
    assert ap.overrides() == []
    ap2 = make_autopilot(state=(0.0, 0.0, 0.0, 5.0, 0.0, 0.0))
    ap2.ekf_origin = None  # never answers GPS_GLOBAL_ORIGIN
    result, console = run_loop(ap2, vclock, scenario, StubController())
    assert result.exit_code == EXIT_GOAL
    assert "note: no GPS_GLOBAL_ORIGIN within 5 s" in console


def test_a_blocked_way_is_a_hold_told_to_the_ground_station(make_autopilot, vclock, tmp_path):
    """The barge of blocked.toml 9 m ahead of a boat at rest: the NMPC holds the boat and
    the bridge says so once, in its log and as STATUSTEXT, and keeps control (no failsafe)."""
    from bridge.lidar import SimLidarSource
    from scenarios.loop.controllers import NmpcController

    scenario = load_scenario(ROOT / "scenarios" / "blocked.toml")
    ap = make_autopilot(state=(131.0, 0.0, 0.0, 0.0, 0.0, 0.0))  # about where it should stop
    result, console = run_loop(ap, vclock, scenario, NmpcController(scenario), log_dir=tmp_path,
                               lidar=SimLidarSource(scenario), duration_s=3.0)
    assert result.exit_code == EXIT_STOPPED and result.failsafes == []
    texts = [e for e in events(ap) if e.startswith("text: canalnav: waiting")]
    assert len(texts) == 1 and "way blocked" in texts[0], events(ap)
    rows = read_steps(tmp_path)
    said = [r["status"] for r in rows if not r["x_m"] and r["status"].startswith("waiting")]
    assert len(said) == 1 and "way blocked" in said[0]
    driven = [r for r in rows if r["x_m"]]
    assert max(abs(float(r["nT_cmd_pct"])) for r in driven[-10:]) < 5.0  # no drive at it
    assert all(r["current_n_mps"] for r in driven)  # the water estimate is logged each step
    assert "way blocked" in console


def test_vessels_are_tracked_on_the_bridge_and_logged(make_autopilot, vclock, tmp_path):
    """A boat coming the other way in the simulated LiDAR: the bridge's perception tracks it,
    hands the NMPC the track, and writes it to tracks.csv as it goes."""
    from bridge.lidar import SimLidarSource
    from scenarios.loop.controllers import NmpcController
    from scenarios.scenario_file import parse_scenario

    text = (ROOT / "scenarios" / "straight.toml").read_text() + """
[[vessel]]
name = "tour boat"
[vessel.hull]
length_m = 10.0
beam_m = 3.0
height_m = 2.0
[vessel.route]
waypoints = [[60, -4], [0, -4]]
speed_mps = 2.0
"""
    scenario = parse_scenario(text, "straight+vessel.toml")
    ap = make_autopilot(state=tuple(scenario.initial_state))
    seen = []
    core = NmpcController(scenario)

    class Watching:
        name = "nmpc"

        def step(self, time_s, state, actuators, segments, blind=False, vessels=()):
            seen.append(tuple(vessels))
            return core.step(time_s, state, actuators, segments, blind=blind, vessels=vessels)

    result, _ = run_loop(ap, vclock, scenario, Watching(), log_dir=tmp_path,
                         lidar=SimLidarSource(scenario), duration_s=4.0)
    assert result.exit_code == EXIT_STOPPED and result.failsafes == []
    assert seen and len(seen[-1]) == 1
    tr = seen[-1][0]
    assert tr.moving and tr.velocity[0] == pytest.approx(-2.0, abs=0.4)
    with open(tmp_path / "tracks.csv") as fh:
        tracks = list(csv.DictReader(fh))
    assert tracks and {r["id"] for r in tracks} == {str(tr.id)}
    rows = [r for r in read_steps(tmp_path) if r["x_m"]]
    assert int(rows[-1]["tracks"]) == 1 and rows[-1]["blind"] == "0"


def test_bridge_writes_run_mcap_on_its_clock(make_autopilot, vclock, tmp_path):
    """--log DIR with the viz extra: run.mcap beside steps.csv, a pose, cloud, segments and
    figures per step at the times of steps.csv, and the position as a LocationFix."""
    pytest.importorskip("foxglove")
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    from bridge.lidar import SimLidarSource
    from bridge.onboard.step_log import BridgeViz
    from controller.geodetic import geodetic_to_ned
    from scenarios.loop.controllers import NmpcController
    from scenarios.results.mcap_log import TOPICS, VizOptions
    from scenarios.sensors.lidar import LidarConfig

    scenario = load_scenario(STRAIGHT)
    ap = make_autopilot(state=tuple(scenario.initial_state))
    viz = BridgeViz(VizOptions(mcap_path=tmp_path / "run.mcap"), OPTIONS.origin,
                    LidarConfig().mounts, separation_m=5.0)
    result, _ = run_loop(ap, vclock, scenario, NmpcController(scenario), log_dir=tmp_path,
                         lidar=SimLidarSource(scenario), duration_s=1.0, viz=viz)
    assert result.steps == 10
    rows = [r for r in read_steps(tmp_path) if r["x_m"]]
    msgs, factory, decoders = {}, DecoderFactory(), {}
    with open(tmp_path / "run.mcap", "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages():
            if channel.message_encoding == "json":
                decoded = json.loads(message.data)
            else:
                if schema.id not in decoders:
                    decoders[schema.id] = factory.decoder_for(channel.message_encoding, schema)
                decoded = decoders[schema.id](message.data)
            msgs.setdefault(channel.topic, []).append((message.log_time, decoded))
    for k in ("tf", "cloud", "segments", "plan", "fix"):
        assert len(msgs[TOPICS[k]]) == len(rows), k
    steps = [m for m in msgs[TOPICS["figures"]] if "solve_ms" in m[1]]
    assert len(steps) == len(rows)
    assert any("time limit" in m[1]["status"] for m in msgs[TOPICS["figures"]])  # an event
    for row, (t_ns, tf), (_, fix), (_, fig) in zip(rows, msgs[TOPICS["tf"]], msgs[TOPICS["fix"]],
                                                   steps):
        assert t_ns == round(float(row["time_s"]) * 1e9)
        boat = {f.child_frame_id: f for f in tf.transforms}["boat"]
        assert boat.translation.x == pytest.approx(float(row["pred_x_m"]), abs=1e-9)
        assert boat.translation.y == pytest.approx(float(row["pred_y_m"]), abs=1e-9)
        n, e = geodetic_to_ned(fix.latitude, fix.longitude, OPTIONS.origin)
        assert (n, e) == pytest.approx((float(row["x_m"]), float(row["y_m"])), abs=1e-3)
        assert fig["throttle_pwm_us"] == float(row["throttle_pwm_us"])
    assert len(msgs[TOPICS["cloud"]][0][1].data) > 12 * 100


class SlowController(StubController):
    """A controller whose steps take `busy_s` of the clock at the calls given (a busy
    computer): the loop falls behind."""

    def __init__(self, clock, busy_s: dict, **kwargs):
        super().__init__(**kwargs)
        self.clock, self.busy_s = clock, busy_s

    def step(self, time_s, state, actuators, segments):
        decision = super().step(time_s, state, actuators, segments)
        self.clock.sleep(self.busy_s.get(len(self.calls), 0.0))
        return decision


def test_a_loop_that_falls_behind_says_so(make_autopilot, vclock, scenario):
    """Steps 5-24 take 0.2 s (each next step late), step 40 takes 1.2 s (a gap): the
    warning once the late steps are ten, the gap each time, to the console and the ground
    station, and the count at the end and in the result."""
    ap = make_autopilot(state=(0.0, 0.0, 0.0, 2.0, 0.0, 0.0))
    busy = {k: 0.2 for k in range(5, 25)} | {40: 1.2}
    result, console = run_loop(ap, vclock, scenario, SlowController(vclock, busy, command=(20, 0)),
                               mode="MANUAL", stale_s=5.0)
    assert result.exit_code == EXIT_GOAL
    assert result.late_steps == 21 and result.gaps == 1
    assert 1.05 < result.worst_late_s < 1.3
    assert console.count("bridge: warning: control loop falls behind the clock") == 1
    assert console.count("bridge: warning: control loop: a gap of 1.2") == 1
    assert f"control loop: 21 of {result.steps} steps late" in console
    texts = [e for e in events(ap) if e.startswith("text: canalnav: control loop")]
    assert len(texts) == 2


def test_lateness_counts_late_steps_and_gaps_and_forgets_a_pause():
    from bridge.onboard.lateness import Lateness

    late = Lateness(0.1)
    times = [0.0, 0.1, 0.2, 0.4, 0.5, 2.0, 2.1]
    said = [late.tick(t)[1] for t in times]
    assert late.late_steps == 2 and late.gaps == 1 and abs(late.worst_late_s - 1.4) < 1e-9
    assert said[5].startswith("control loop: a gap of 1.50 s before step 6")
    late.pause()
    assert late.tick(30.0) == (0.1, None) and late.late_steps == 2
    assert Lateness(0.1).summary() is None
