"""AutopilotLink against a scripted fake autopilot over loopback UDP, in lock-step (VirtualClock).

The fake decodes what arrives, so PWM, steering sense and the release values are checked
where the autopilot would see them.
"""

from __future__ import annotations

import math
import socket
import struct
import time

import numpy as np
import pytest

from bridge.shared.ardupilot import DEFAULT_PARAMS
from bridge.onboard.link import AutopilotLink, LinkError, parse_url
from controller.pwm import CommandChannels
from controller.errors import InputError
from pymavlink import mavutil

KEY = bytes(range(32))


def connect(ap, clock, **kwargs) -> AutopilotLink:
    link = AutopilotLink(ap.url, clock, **kwargs)
    link.wait_heartbeat(5.0)
    return link


def test_heartbeat_identifies_as_onboard_controller_and_locks_onto_the_autopilot(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock)
    hb = ap.messages("HEARTBEAT")[0]
    assert hb.type == mavutil.mavlink.MAV_TYPE_ONBOARD_CONTROLLER
    assert hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_INVALID
    assert (hb.get_srcSystem(), hb.get_srcComponent()) == (255, 191)
    assert link.heartbeat.mode == "MANUAL" and not link.heartbeat.armed
    assert (link.target_system, link.target_component) == (1, 1)
    assert hb.get_msgbuf()[0] == 0xFD  # MAVLink 2 on the wire
    link.wait_until(lambda: False, 2.5)
    n = len(ap.messages("HEARTBEAT"))
    assert 3 <= n <= 4  # 1 Hz
    assert link.alive
    link.close()


def test_wait_heartbeat_refuses_a_vehicle_that_is_not_a_boat_or_rover(make_autopilot, vclock):
    ap = make_autopilot(vehicle_type=2)  # quadrotor
    link = AutopilotLink(ap.url, vclock)
    with pytest.raises(LinkError, match="not a boat or rover"):
        link.wait_heartbeat(3.0)
    link.close()


def test_wait_heartbeat_times_out_with_a_clear_error(vclock, udp_port):
    link = AutopilotLink(f"udpout:127.0.0.1:{udp_port()}", vclock)
    with pytest.raises(LinkError, match="no heartbeat from an autopilot"):
        link.wait_heartbeat(0.5)
    link.close()


def test_streams_requested_with_set_message_interval_and_state_follows(make_autopilot, vclock):
    ap = make_autopilot(state=(10.0, -5.0, math.radians(30), 2.0, 0.0, 0.0))
    link = connect(ap, vclock)
    results = link.request_streams(20)
    assert results == {k: 0 for k in ("ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT",
                                      "EKF_STATUS_REPORT")}
    cmds = [m for m in ap.messages("COMMAND_LONG") if m.command == 511]
    assert [int(m.param1) for m in cmds] == [30, 32, 33, 193]
    assert all(m.param2 == pytest.approx(50_000) for m in cmds)
    state = link.wait_position_ok(2.0)
    truth = ap.state
    assert state.x == pytest.approx(truth[0], abs=0.1) and state.y == pytest.approx(truth[1], abs=0.1)
    assert state.psi == pytest.approx(math.radians(30), abs=1e-6)
    assert state.u == pytest.approx(2.0, abs=1e-6) and state.v == pytest.approx(0.0, abs=1e-6)
    assert link.state_age_s <= 0.1
    assert 0 < link.link_delay_s <= 0.02  # TIMESYNC round trip of one or two ticks, halved
    link.close()


def test_set_message_interval_retries_until_acknowledged(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock)
    ap.deaf = True
    assert link.request_streams(20, messages=("ATTITUDE",)) == {"ATTITUDE": None}
    ap.deaf = False
    link.close()


def test_state_from_global_position_with_a_geodetic_origin(make_autopilot, vclock):
    origin = (36.03, 129.37, 0.0)
    ap = make_autopilot(state=(120.0, 35.0, 1.0, 1.5, 0.2, 0.0), geodetic_origin=origin)
    link = connect(ap, vclock, geodetic_origin=origin)
    link.request_streams(20)
    state = link.wait_position_ok(2.0)
    assert state.x == pytest.approx(ap.state[0], abs=0.2)
    assert state.y == pytest.approx(ap.state[1], abs=0.2)
    assert state.u == pytest.approx(1.5, abs=0.02) and state.v == pytest.approx(0.2, abs=0.02)
    link.close()


def test_fetch_params_by_name_accepts_either_alias(make_autopilot, vclock):
    ap = make_autopilot(params={"RC_OPTIONS": 0.0, "MAV_GCS_SYSID": 250.0})
    link = connect(ap, vclock)
    got = link.fetch_params(["RC_OPTIONS", "SYSID_MYGCS"], optional=("MAV_GCS_SYSID_HI",),
                            timeout_s=0.3)
    assert got == {"RC_OPTIONS": 0.0, "SYSID_MYGCS": 250.0, "MAV_GCS_SYSID": 250.0}
    asked = [m.param_id for m in ap.messages("PARAM_REQUEST_READ")]
    assert {"SYSID_MYGCS", "MAV_GCS_SYSID", "MAV_GCS_SYSID_HI"} <= set(asked)
    # old firmware: only the old name exists
    del ap.params["MAV_GCS_SYSID"]
    ap.params["SYSID_MYGCS"] = 254.0
    got = link.fetch_params(["MAV_GCS_SYSID"], timeout_s=0.3)
    assert got == {"SYSID_MYGCS": 254.0, "MAV_GCS_SYSID": 254.0}
    link.close()


def test_fetch_params_retries_and_leaves_out_unknown_names(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock)
    got = link.fetch_params(["RC1_MIN", "NO_SUCH_PARAM"], timeout_s=0.2, retries=3)
    assert got == {"RC1_MIN": 1100.0}
    asked = [m.param_id for m in ap.messages("PARAM_REQUEST_READ")]
    assert asked.count("NO_SUCH_PARAM") == 3
    link.close()


CALIBRATED = {
    "RCMAP_ROLL": 2, "RCMAP_THROTTLE": 4,
    "RC2_MIN": 1000, "RC2_MAX": 2000, "RC2_TRIM": 1450, "RC2_DZ": 20, "RC2_REVERSED": 0,
    "RC4_MIN": 1200, "RC4_MAX": 1800, "RC4_TRIM": 1500, "RC4_DZ": 0, "RC4_REVERSED": 1,
}


def last_override(ap, link):
    link.wait_until(lambda: False, 0.03)
    return ap.overrides()[-1]


def test_pwm_through_send_commands_with_non_default_calibration_and_mapping(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock)
    link.rc_mapping = CommandChannels.from_rc_params(CALIBRATED)
    sent = link.send_commands(50.0, 30.0)
    chans = last_override(ap, link)
    # steering ch2: nS = +30 (port) is below trim: 1450 - 20 - 0.3 * (1430 - 1000) = 1301
    # throttle ch4, reversed: +50 % goes below trim: 1500 - 0.5 * (1500 - 1200) = 1350
    assert chans[1] == 1301 and chans[3] == 1350
    assert sent == {2: 1301, 4: 1350}
    assert [chans[i] for i in (0, 2, 4, 5, 6, 7)] == [65535] * 6  # 1..8 untouched
    assert chans[8:] == [0] * 10  # 9..18: 0 = ignore
    link.close()


def test_steering_sense_both_ways(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock)
    link.rc_mapping = CommandChannels.from_rc_params(DEFAULT_PARAMS)  # steering 1, throttle 3, DZ 30
    link.send_commands(0.0, 40.0)  # port
    port = last_override(ap, link)
    link.send_commands(0.0, -40.0)  # starboard
    starboard = last_override(ap, link)
    assert port[0] < 1500 < starboard[0]
    # dead zone 30 us: 1500 - 30 - 0.4 * 370 = 1322; 1500 + 30 + 0.4 * 370 = 1678
    assert (port[0], starboard[0]) == (1322, 1678)
    assert port[2] == starboard[2] == 1500  # throttle at trim
    # as the autopilot reads them back
    m = link.rc_mapping
    assert m.to_commands({1: port[0], 3: port[2]}) == pytest.approx((0.0, 40.0))
    link.close()


def test_neutral_and_release(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock)
    link.rc_mapping = CommandChannels.from_rc_params(CALIBRATED)
    link.send_neutral()
    neutral = last_override(ap, link)
    assert (neutral[1], neutral[3]) == (1450, 1500)
    link.release()
    assert last_override(ap, link) == [0] * 8 + [0] * 10
    # a channel above 8 is released with UINT16_MAX - 1 (0 would mean "ignore" there)
    link.rc_mapping = CommandChannels.from_rc_params({**CALIBRATED, "RCMAP_THROTTLE": 9})
    link.send_commands(20.0, 0.0)
    chans = last_override(ap, link)
    assert chans[8] == 1500 + 80 and chans[3] == 65535
    link.release()
    chans = last_override(ap, link)
    assert chans[:8] == [0] * 8 and chans[8] == 65534 and chans[9:] == [0] * 9
    link.close()


def test_send_commands_needs_the_mapping(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock)
    with pytest.raises(LinkError, match="RC mapping"):
        link.send_commands(10, 0)
    link.close()


def test_arm_and_set_mode_check_the_acknowledgement(make_autopilot, vclock):
    ap = make_autopilot(mode="HOLD")
    link = connect(ap, vclock)
    link.set_mode("manual")
    assert ap.mode_name == "MANUAL"
    link.arm()
    assert ap.armed
    ap.ack_results[mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM] = mavutil.mavlink.MAV_RESULT_DENIED
    ap.mav.statustext_send(mavutil.mavlink.MAV_SEVERITY_CRITICAL, b"PreArm: Throttle armed")
    with pytest.raises(LinkError, match=r"refused to arm \(MAV_RESULT_DENIED\): PreArm: Throttle armed"):
        link.arm()
    with pytest.raises(InputError, match="not a Rover mode"):
        link.set_mode("LAND")
    ap.deaf = True
    with pytest.raises(LinkError, match="no answer to mode HOLD"):
        link.set_mode("HOLD", timeout_s=0.1, retries=2)
    link.close()


def test_statustext_reaches_the_autopilot_and_long_text_is_chunked(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock)
    link.statustext("canalnav: short", 2)
    link.statustext("x" * 120, 4)
    link.wait_until(lambda: False, 0.05)
    texts = ap.messages("STATUSTEXT")
    assert texts[0].text == "canalnav: short" and texts[0].severity == 2
    assert [t.chunk_seq for t in texts[1:]] == [0, 1, 2]
    assert "".join(t.text for t in texts[1:]) == "x" * 120
    assert len({t.id for t in texts[1:]}) == 1
    link.close()


def test_alive_and_stale_on_the_clock(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock, link_timeout_s=3.0, stale_s=1.0)
    link.request_streams(20)
    link.wait_position_ok(2.0)
    ap.send_state = False  # heartbeats and EKF status only
    link.wait_until(lambda: False, 1.2)
    assert link.alive and not link.state_fresh and link.state_age_s > 1.0
    ap.mute = True
    link.wait_until(lambda: False, 2.0)
    assert link.alive
    link.wait_until(lambda: False, 1.5)
    assert not link.alive and link.silence_s > 3.0
    link.close()


def test_stranger_system_id_is_ignored(make_autopilot, vclock):
    ap = make_autopilot(state=(0, 0, 0, 0, 0, 0))
    link = connect(ap, vclock)
    link.request_streams(20)
    link.wait_position_ok(2.0)
    port = link._conn.port.getsockname()[1]
    stranger = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=42,
                                          source_component=1, dialect="ardupilotmega")
    for _ in range(5):
        stranger.mav.heartbeat_send(11, 3, 0, 4, 4)
        stranger.mav.local_position_ned_send(10**6, 500.0, 500.0, 0, 0, 0, 0)
        stranger.mav.attitude_send(10**6, 0, 0, 2.0, 0, 0, 0)
    link.wait_until(lambda: False, 0.2)
    assert link.counters.ignored_other_source >= 15
    assert link.target_system == 1 and link.heartbeat.system_id == 1 and link.heartbeat.mode == "MANUAL"
    assert abs(link.state.x) < 1 and abs(link.state.psi) < 1e-6
    stranger.close()
    link.close()


def test_garbage_is_counted_and_skipped(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock)
    link.request_streams(20)
    link.wait_position_ok(2.0)
    rng = np.random.default_rng(7)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    target = ("127.0.0.1", link._conn.port.getsockname()[1])
    for _ in range(200):
        sock.sendto(rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8).tobytes(), target)
    sock.close()
    before = link.state.time_boot_s
    link.wait_until(lambda: False, 0.5)
    assert link.counters.bad_data > 0
    assert link.state.time_boot_s > before and link.state_fresh and link.alive
    link.close()


def test_signing_rejects_unsigned_messages(make_autopilot, vclock):
    ap = make_autopilot(signing_key=KEY)
    link = connect(ap, vclock, signing_key=KEY)
    link.request_streams(20)
    link.wait_position_ok(2.0)
    assert ap.messages("HEARTBEAT")[0].get_signed()  # our messages are signed
    port = link._conn.port.getsockname()[1]
    spoof = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1,
                                       source_component=1, dialect="ardupilotmega")
    for _ in range(5):
        spoof.mav.local_position_ned_send(10**6, 500.0, 500.0, 0, 0, 0, 0)
    link.wait_until(lambda: False, 0.1)
    assert link.counters.rejected_signature >= 5
    assert abs(link.state.x - ap.state[0]) < 1.0
    spoof.close()
    link.close()


def test_signing_on_and_an_unsigned_autopilot_is_never_heard(make_autopilot, vclock):
    ap = make_autopilot(signing_key=KEY, sign=False)
    link = AutopilotLink(ap.url, vclock, signing_key=KEY)
    with pytest.raises(LinkError, match="no heartbeat"):
        link.wait_heartbeat(1.5)
    assert link.counters.rejected_signature >= 1
    link.close()


def test_a_wrong_key_is_rejected_too(make_autopilot, vclock):
    ap = make_autopilot(signing_key=bytes(32))
    link = AutopilotLink(ap.url, vclock, signing_key=KEY)
    with pytest.raises(LinkError, match="no heartbeat"):
        link.wait_heartbeat(1.5)
    assert link.counters.rejected_signature >= 1
    link.close()


def test_target_system_option_ignores_other_autopilots(make_autopilot, vclock):
    ap = make_autopilot(system_id=7)
    link = AutopilotLink(ap.url, vclock, target_system=3)
    with pytest.raises(LinkError, match="no heartbeat from system 3"):
        link.wait_heartbeat(1.5)
    link.close()


def test_autopilot_restart_is_noticed(make_autopilot, vclock):
    ap = make_autopilot()
    link = connect(ap, vclock)
    link.request_streams(20)
    link.wait_until(lambda: False, 3.0)
    old = link.state
    ap.restart()
    link.wait_until(lambda: False, 1.2)
    assert link.state is old and not link.state_fresh  # the rebooted autopilot forgot the rates
    link.request_streams(20)
    link.wait_until(lambda: False, 0.2)
    assert link.counters.autopilot_restarts == 1
    assert link.state.time_boot_s < old.time_boot_s and link.state_fresh
    link.close()


def test_tlog_holds_sent_and_received_messages(make_autopilot, vclock, tmp_path):
    ap = make_autopilot()
    path = tmp_path / "link.tlog"
    link = connect(ap, vclock, tlog_path=path)
    link.rc_mapping = CommandChannels.from_rc_params({})
    link.send_commands(10, 0)
    link.request_streams(20)
    link.wait_until(lambda: False, 0.3)
    link.close()
    data = path.read_bytes()
    stamps, kinds, i = [], [], 0
    parser = mavutil.mavlink.MAVLink(None)
    while i < len(data):
        (usec,) = struct.unpack(">Q", data[i:i + 8])
        msg = parser.parse_char(data[i + 8:])
        assert msg is not None
        n = len(msg.get_msgbuf())
        kinds.append((usec & 3, msg.get_type(), msg.get_srcSystem()))
        stamps.append(usec)
        parser = mavutil.mavlink.MAVLink(None)
        i += 8 + n
    assert (3, "RC_CHANNELS_OVERRIDE", 255) in kinds and (3, "HEARTBEAT", 255) in kinds
    assert (0, "HEARTBEAT", 1) in kinds and (0, "ATTITUDE", 1) in kinds
    assert stamps == sorted(stamps) and abs(stamps[0] / 1e6 - time.time()) < 3600  # epoch us
    # pymavlink reads it as a tlog
    log = mavutil.mavlink_connection(str(path))
    assert log.recv_match(type="RC_CHANNELS_OVERRIDE") is not None


def test_bad_urls_and_options_are_input_errors(vclock):
    with pytest.raises(InputError, match="cannot open the MAVLink connection"):
        AutopilotLink("udpin:nonsense", vclock)
    with pytest.raises(InputError, match="cannot open"):
        AutopilotLink("/dev/no-such-serial-device", vclock)
    with pytest.raises(InputError, match="baud"):
        AutopilotLink("/dev/ttyACM0,fast", vclock)
    with pytest.raises(InputError, match="signing key must be 32 bytes"):
        AutopilotLink("udpout:127.0.0.1:9", vclock, signing_key=b"short")
    with pytest.raises(InputError, match="system id"):
        AutopilotLink("udpout:127.0.0.1:9", vclock, system_id=0)
    assert parse_url("/dev/ttyUSB0,57600") == ("/dev/ttyUSB0", 57600)
    assert parse_url("udpin:0.0.0.0:14550") == ("udpin:0.0.0.0:14550", 115200)


def test_a_refused_tcp_link_is_one_clear_error_without_pymavlinks_chatter(capsys, vclock):
    """Issue 35: pymavlink printed "Connection refused sleeping" for each try before the
    error; now the error alone says how many tries were made."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nobody listens there now
    with pytest.raises(InputError, match=r"cannot open the MAVLink connection .* after \d+ tries"):
        AutopilotLink(f"tcp:127.0.0.1:{port}", vclock)
    assert "sleeping" not in capsys.readouterr().out
