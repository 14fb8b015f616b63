"""The simulated ArduPilot Rover: MAVLink behaviour seen from a pymavlink client, in lock-step.

Each test runs the simulator and a client in one thread over real loopback UDP: the client
sends, `clock.sleep` advances virtual time (pumping the simulator), the client reads.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest

from bridge.shared import ardupilot
from bridge.autopilot_sim.rc import RcInput
from bridge.autopilot_sim.rover import AutopilotSim, open_connection
from bridge.shared.clock import VirtualClock
from bridge.main import main
from bridge.autopilot_sim.plant import free_udp_port
from bridge.shared.signing import load_signing_key
from controller.errors import InputError
from scenarios.scenario_file import load_scenario

from .rigs import SimRig

ROOT = Path(__file__).resolve().parents[2]
STRAIGHT = ROOT / "scenarios" / "straight.toml"
KEY = bytes(range(32))

# MAVLink numbers used below (common.xml).
CMD_ARM, CMD_DO_SET_MODE, CMD_SET_INTERVAL, CMD_GET_INTERVAL = 400, 176, 511, 510
CMD_REBOOT = 246
ACCEPTED, DENIED, UNSUPPORTED, FAILED = 0, 2, 3, 4
ID_ATTITUDE, ID_RC_CHANNELS, ID_GPS_RAW_INT = 30, 65, 24
CUSTOM = 1  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
SAFETY_ARMED = 128
EKF_POS_HORIZ_ABS = 16


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(STRAIGHT)


class Rig(SimRig):
    """The simulator on its virtual clock (tests/bridge/rigs.py, no link of the bridge's) and
    pymavlink clients, stepped together."""

    def __init__(self, scenario, work_dir, **kwargs):
        kwargs.setdefault("ekf_delay_s", 1.0)
        kwargs.setdefault("init_s", 0.0)  # running at once (start-up has its own test)
        super().__init__(scenario, work_dir, link=False, **kwargs)
        self.sim = self.autopilot
        self.clients = []
        self.client = self.connect()

    def connect(self, sysid: int = 255, key: bytes | None = None):
        c = open_connection(f"udpout:127.0.0.1:{self.port}", sysid, 190)
        if key is not None:
            c.setup_signing(key, sign_outgoing=True)
        c.mav.heartbeat_send(6, 8, 0, 0, 0)  # MAV_TYPE_GCS: the simulator learns our address
        c.inbox = []
        self.clients.append(c)
        return c

    def run(self, seconds: float) -> list:
        """Advance `seconds` of virtual time; everything the main client received meanwhile."""
        self.clock.sleep(seconds)
        return self.read()

    def read(self, client=None) -> list:
        client = client or self.client
        got = []
        while (m := client.recv_match(blocking=False)) is not None:
            if m.get_type() != "BAD_DATA":
                got.append(m)
        client.inbox.extend(got)
        return got

    def wait(self, kind: str, cond=lambda m: True, timeout_s: float = 2.0, client=None):
        """The first `kind` message matching `cond` within `timeout_s` of virtual time."""
        client = client or self.client
        for _ in range(int(round(timeout_s / self.clock.tick_s))):
            self.clock.sleep(self.clock.tick_s)
            for m in self.read(client):
                if m.get_type() == kind and cond(m):
                    return m
        return None

    def command(self, cmd: int, *params, client=None):
        client = client or self.client
        p = list(params) + [0.0] * (7 - len(params))
        client.mav.command_long_send(1, 1, cmd, 0, *p)
        return self.wait("COMMAND_ACK", lambda m: m.command == cmd, client=client)

    def param(self, name: str):
        self.client.mav.param_request_read_send(1, 1, name.encode(), -1)
        return self.wait("PARAM_VALUE", lambda m: m.param_id == name, timeout_s=0.2)

    def set_param(self, name: str, value: float):
        self.client.mav.param_set_send(1, 1, name.encode(), value, 9)
        return self.wait("PARAM_VALUE", lambda m: m.param_id == name, timeout_s=0.2)

    def override(self, client=None, target: int = 1, **chans):
        """RC_CHANNELS_OVERRIDE with chanN=value; unnamed channels 1-8 'leave as is'."""
        client = client or self.client
        values = [chans.get(f"ch{i}", 65535 if i <= 8 else 0) for i in range(1, 19)]
        client.mav.rc_channels_override_send(target, 1, *values)

    def arm(self):
        ack = self.command(CMD_ARM, 1, ardupilot.FORCE_ARM_MAGIC)
        assert ack.result == ACCEPTED and self.sim.armed

    def close(self):
        for c in self.clients:
            c.close()
        self.clients = []
        super().close()


@pytest.fixture
def make_rig(scenario, sim_rig):
    return lambda **kwargs: sim_rig(scenario, kind=Rig, **kwargs)


# -- heartbeat and parameters -----------------------------------------------------------------
def test_heartbeat_says_boat_ardupilot_manual_disarmed_mavlink2(make_rig):
    rig = make_rig(system_id=7)
    hb = rig.wait("HEARTBEAT")
    assert hb is not None
    assert hb.get_srcSystem() == 7 and hb.get_srcComponent() == 1
    assert hb.type == 11 and hb.autopilot == 3  # MAV_TYPE_SURFACE_BOAT, ARDUPILOTMEGA
    assert hb.base_mode & CUSTOM and not hb.base_mode & SAFETY_ARMED
    assert hb.custom_mode == ardupilot.MODES["MANUAL"]
    assert hb.system_status == 4  # MAV_STATE_ACTIVE: Rover says STANDBY only in HOLD
    assert hb.get_msgbuf()[0] == 253  # MAVLink 2 frame
    beats = [m for m in rig.run(3.0) if m.get_type() == "HEARTBEAT"]
    assert 2 <= len(beats) <= 4  # 1 Hz


def test_start_up_like_rover(make_rig):
    """INITIALISING and CALIBRATING for init_s, dead zones 0 until start-up sets them to 30
    (without a PARAM_VALUE), arming and modes refused meanwhile; a stored value stays."""
    rig = make_rig(init_s=2.0, params={"RC3_DZ": 45})
    hb = rig.wait("HEARTBEAT")
    assert hb.custom_mode == ardupilot.MODES["INITIALISING"] and hb.system_status == 2
    assert rig.param("RC1_DZ").param_value == 0  # not yet Rover's 30 us
    assert rig.param("RC3_DZ").param_value == 45  # stored: start-up leaves it alone
    assert rig.command(CMD_ARM, 1).result == 1  # MAV_RESULT_TEMPORARILY_REJECTED
    assert rig.command(CMD_DO_SET_MODE, CUSTOM, ardupilot.MODES["HOLD"]).result == 1
    rig.client.inbox.clear()
    hb = rig.wait("HEARTBEAT", lambda m: m.custom_mode == ardupilot.MODES["MANUAL"], timeout_s=3.0)
    assert hb.system_status == 4 and rig.sim.initialised
    assert not any(m.get_type() == "PARAM_VALUE" for m in rig.client.inbox)  # set silently
    assert rig.param("RC1_DZ").param_value == 30
    assert rig.command(CMD_ARM, 1, ardupilot.FORCE_ARM_MAGIC).result == ACCEPTED
    # a change from anyone is sent to all
    rig.sim.set_param("RC1_TRIM", 1490)
    assert rig.wait("PARAM_VALUE", lambda m: m.param_id == "RC1_TRIM").param_value == 1490
    # a reboot starts up again: the dead zone reads 0 until it is over
    rig.command(CMD_ARM, 0)
    rig.sim.restart()
    assert rig.param("RC1_DZ").param_value == 0 and not rig.sim.initialised


def test_parameters_read_by_name_and_index_list_and_set(make_rig):
    calib = {"RCMAP_ROLL": 2, "RC2_MIN": 1000, "RC2_MAX": 2000, "RC2_TRIM": 1520, "RC2_DZ": 10}
    rig = make_rig(params=calib)
    pv = rig.param("RC2_MIN")
    assert pv.param_value == 1000 and pv.param_type == 9  # MAV_PARAM_TYPE_REAL32
    assert pv.param_count == len(rig.sim.params) and 0 <= pv.param_index < pv.param_count
    rig.client.mav.param_request_read_send(1, 1, b"", pv.param_index)
    by_index = rig.wait("PARAM_VALUE", lambda m: m.param_index == pv.param_index)
    assert by_index.param_id == "RC2_MIN"
    assert rig.param("RCMAP_ROLL").param_value == 2
    assert rig.param("MAV_GCS_SYSID").param_value == 255
    assert rig.param("SYSID_MYGCS") is None  # the old name does not exist in 4.7

    rig.client.inbox.clear()
    rig.client.mav.param_request_list_send(1, 1)
    rig.run(0.5)
    listed = {m.param_id: m for m in rig.client.inbox if m.get_type() == "PARAM_VALUE"}
    assert set(listed) == set(rig.sim.params)
    assert sorted(m.param_index for m in listed.values()) == list(range(len(listed)))
    assert listed["RC2_TRIM"].param_value == 1520 and listed["SYSID_THISMAV"].param_value == 1

    assert rig.set_param("RC_OVERRIDE_TIME", 1.5).param_value == 1.5
    assert rig.sim.params["RC_OVERRIDE_TIME"] == 1.5
    before = rig.sim.params
    assert rig.set_param("NO_SUCH_PARAM", 3.0) is None  # ignored silently, as ArduPilot
    assert rig.sim.params == before


def test_legacy_parameter_names(make_rig, scenario, tmp_path):
    rig = make_rig(legacy_param_names=True, params={"ARMING_CHECK": 0})
    assert rig.param("SYSID_MYGCS").param_value == 255
    assert rig.param("ARMING_CHECK").param_value == 0
    assert rig.param("MAV_GCS_SYSID") is None and rig.param("ARMING_SKIPCHK") is None
    # ARMING_CHECK = 0: no checks, arming works before the EKF is ready
    assert rig.command(CMD_ARM, 1).result == ACCEPTED
    with pytest.raises(InputError, match="SYSID_MYGCS.*legacy"):
        AutopilotSim(scenario, "udpin:127.0.0.1:0", VirtualClock(), params={"SYSID_MYGCS": 7},
                     work_dir=tmp_path)


# -- streams and commands ---------------------------------------------------------------------
def test_set_message_interval_acks_and_rates(make_rig):
    rig = make_rig()
    assert rig.command(CMD_SET_INTERVAL, ID_RC_CHANNELS, 50_000).result == ACCEPTED
    assert rig.command(CMD_SET_INTERVAL, ID_ATTITUDE, -1).result == ACCEPTED
    got = rig.run(2.0)
    n_rc = sum(m.get_type() == "RC_CHANNELS" for m in got)
    assert 36 <= n_rc <= 44  # 20 Hz
    assert not any(m.get_type() == "ATTITUDE" for m in got)
    assert rig.command(CMD_SET_INTERVAL, ID_ATTITUDE, 0).result == ACCEPTED  # back to default
    n_att = sum(m.get_type() == "ATTITUDE" for m in rig.run(2.0))
    assert 6 <= n_att <= 10  # 4 Hz
    rig.client.inbox.clear()
    assert rig.command(CMD_GET_INTERVAL, ID_RC_CHANNELS).result == ACCEPTED
    mi = [m for m in rig.client.inbox if m.get_type() == "MESSAGE_INTERVAL"]
    assert [(m.message_id, m.interval_us) for m in mi] == [(ID_RC_CHANNELS, 50_000)]
    assert rig.command(CMD_SET_INTERVAL, ID_GPS_RAW_INT, 100_000).result == DENIED
    assert rig.command(31999).result == UNSUPPORTED  # every command is answered
    rig.client.mav.command_int_send(1, 1, 0, CMD_SET_INTERVAL, 0, 0, ID_RC_CHANNELS, -1, 0, 0,
                                    0, 0, 0)
    ack = rig.wait("COMMAND_ACK", lambda m: m.command == CMD_SET_INTERVAL)
    assert ack.result == ACCEPTED and ack.target_system == 255
    rig.run(0.1)
    assert not any(m.get_type() == "RC_CHANNELS" for m in rig.run(1.0))


def test_request_message_timesync_and_legacy_data_streams(make_rig):
    rig = make_rig(legacy_param_names=True)
    rig.client.inbox.clear()
    assert rig.command(512, 148).result == ACCEPTED  # REQUEST_MESSAGE AUTOPILOT_VERSION
    rig.run(0.05)
    version = next(m for m in rig.client.inbox if m.get_type() == "AUTOPILOT_VERSION")
    assert version.flight_sw_version >> 16 == 0x0405  # legacy names: ArduPilot 4.5
    assert rig.command(512, ID_GPS_RAW_INT).result == DENIED
    rig.client.mav.timesync_send(0, 123456789)
    ts = rig.wait("TIMESYNC", lambda m: m.ts1 == 123456789)
    assert ts.tc1 > 0
    rig.client.mav.request_data_stream_send(1, 1, 3, 10, 1)  # RC_CHANNELS group at 10 Hz
    rig.client.mav.request_data_stream_send(1, 1, 10, 0, 0)  # EXTRA1 (ATTITUDE) off
    got = rig.run(1.0)
    assert 8 <= sum(m.get_type() == "SERVO_OUTPUT_RAW" for m in got) <= 12
    assert not any(m.get_type() == "ATTITUDE" for m in got)


def test_arming_waits_for_the_ekf(make_rig):
    rig = make_rig(ekf_delay_s=1.0)
    ekf = rig.wait("EKF_STATUS_REPORT")
    assert ekf.flags & 1 and not ekf.flags & EKF_POS_HORIZ_ABS
    assert rig.command(CMD_ARM, 1).result == FAILED
    assert not rig.sim.armed
    assert any("PreArm" in m.text for m in rig.client.inbox if m.get_type() == "STATUSTEXT")
    assert not any(m.get_type() == "LOCAL_POSITION_NED" for m in rig.client.inbox)
    ekf = rig.wait("EKF_STATUS_REPORT", lambda m: m.flags & EKF_POS_HORIZ_ABS, timeout_s=2.0)
    assert ekf is not None and rig.sim.ekf_ready
    assert rig.command(CMD_ARM, 1).result == ACCEPTED and rig.sim.armed
    hb = rig.wait("HEARTBEAT")
    assert hb.base_mode & SAFETY_ARMED and hb.system_status == 4  # MAV_STATE_ACTIVE
    assert rig.command(CMD_ARM, 0).result == ACCEPTED and not rig.sim.armed


@pytest.mark.parametrize("skip", [-1, 1 << 3])
def test_arming_skip_checks(make_rig, skip):
    rig = make_rig(ekf_delay_s=100.0, params={"ARMING_SKIPCHK": skip})
    assert rig.command(CMD_ARM, 1).result == ACCEPTED


def test_mode_changes(make_rig):
    rig = make_rig(ekf_delay_s=30.0)
    assert rig.command(CMD_DO_SET_MODE, CUSTOM, ardupilot.MODES["HOLD"]).result == ACCEPTED
    assert rig.sim.mode == ardupilot.MODES["HOLD"]
    assert rig.wait("HEARTBEAT", lambda m: m.custom_mode == 4) is not None
    assert any(m.text == "Mode HOLD" for m in rig.client.inbox if m.get_type() == "STATUSTEXT")
    assert rig.command(CMD_DO_SET_MODE, CUSTOM, 2).result == FAILED  # no Rover mode 2
    assert rig.command(CMD_DO_SET_MODE, CUSTOM, ardupilot.MODES["AUTO"]).result == FAILED  # no EKF
    assert rig.command(CMD_DO_SET_MODE, 0, 0).result == DENIED  # custom modes only
    assert rig.sim.mode == ardupilot.MODES["HOLD"]
    rig.client.mav.set_mode_send(1, CUSTOM, ardupilot.MODES["MANUAL"])
    assert rig.wait("COMMAND_ACK", lambda m: m.command == 11).result == ACCEPTED
    assert rig.sim.mode == ardupilot.MODES["MANUAL"]


# -- RC overrides -----------------------------------------------------------------------------
def test_override_from_the_gcs_drives_the_boat(make_rig):
    calib = {"RCMAP_ROLL": 2, "RC2_MIN": 1000, "RC2_MAX": 2000, "RC2_TRIM": 1500, "RC2_DZ": 0}
    rig = make_rig(params=calib)
    rig.arm()
    u0 = rig.sim.true_state[3]
    for _ in range(16):
        rig.override(ch3=1900, ch2=1750)  # full throttle; steering half way to starboard
        rig.run(0.5)
    nT, nS = rig.sim.outputs
    assert nT == pytest.approx(100.0) and nS == pytest.approx(-50.0)
    x = rig.sim.true_state
    assert x[3] > u0 + 0.3  # faster than the initial 1 m/s
    assert x[5] > 0.02  # yawing to starboard
    assert rig.sim.actuators[0] > 50  # rate limited, but moving
    rc = rig.command(CMD_SET_INTERVAL, ID_RC_CHANNELS, 100_000)
    assert rc.result == ACCEPTED
    rig.override(ch3=1900, ch2=1750)
    m = rig.wait("RC_CHANNELS")
    assert (m.chan2_raw, m.chan3_raw, m.chan1_raw) == (1750, 1900, 1500)


def test_override_rules(make_rig):
    rig = make_rig()
    rig.arm()
    other = rig.connect(sysid=200)
    rig.override(client=other, ch1=1900, ch3=1900)
    rig.run(0.2)
    assert rig.sim.outputs == (0.0, 0.0)  # not the GCS sysid
    rig.override(target=9, ch1=1900, ch3=1900)
    rig.run(0.2)
    assert rig.sim.outputs == (0.0, 0.0)  # not addressed to us
    assert rig.sim.counters.overrides_ignored == 2

    rig.override(ch1=1900, ch3=1900)
    rig.run(0.2)
    assert rig.sim.outputs[0] > 0 and rig.sim.outputs[1] < 0
    rig.override(ch3=1700)  # ch1 left as it is (65535)
    rig.run(0.2)
    # 170 us of the 370 above the dead zone is 45.9 %: Rover reads whole percent, truncated
    assert rig.sim.outputs[0] == 45.0 and rig.sim.outputs[1] < 0
    rig.override(ch1=0)  # release the steering: back to the receiver's trim
    rig.run(0.2)
    assert rig.sim.outputs[1] == 0.0 and rig.sim.outputs[0] > 0

    assert rig.set_param("RC_OPTIONS", ardupilot.RC_OPTION_IGNORE_OVERRIDES).param_value == 2
    rig.run(0.1)
    assert rig.sim.outputs == (0.0, 0.0)  # existing overrides no longer count
    rig.override(ch1=1900, ch3=1900)
    rig.run(0.2)
    assert rig.sim.outputs == (0.0, 0.0)


def test_override_times_out(make_rig):
    rig = make_rig(params={"RC_OVERRIDE_TIME": 1.0})
    rig.arm()
    rig.override(ch3=1900)
    rig.run(0.5)
    assert rig.sim.outputs[0] == pytest.approx(100.0)
    rig.run(0.6)
    assert rig.sim.outputs == (0.0, 0.0)
    rig.set_param("RC_OVERRIDE_TIME", 0)  # overrides disabled
    rig.override(ch3=1900)
    rig.run(0.2)
    assert rig.sim.outputs == (0.0, 0.0)
    rig.set_param("RC_OVERRIDE_TIME", -1)  # never times out
    rig.override(ch3=1900)
    rig.run(5.0)
    assert rig.sim.outputs[0] == pytest.approx(100.0)
    rig.command(CMD_ARM, 0)
    assert rig.sim.outputs == (0.0, 0.0)  # disarmed: neutral


def test_override_channel_values_follow_the_mavlink_spec():
    rc, params = RcInput(), {"RC_OVERRIDE_TIME": 3.0}
    rc.apply([1600] + [65535] * 7 + [1700] + [0] * 9, 0.0, False)
    assert rc.pwm(1, params, 1.0) == 1600 and rc.pwm(9, params, 1.0) == 1700
    rc.apply([65535] * 8 + [0] + [65535] * 9, 1.0, False)  # 0 and 65535: leave ch9 as it is
    assert rc.pwm(9, params, 2.0) == 1700 and rc.pwm(1, params, 2.0) == 1600
    rc.apply([0] + [65535] * 7 + [65534] + [0] * 9, 2.0, False)  # release ch1 and ch9
    assert rc.pwm(1, params, 2.5) == 1500 and rc.pwm(9, params, 2.5) == 1500


# -- robustness, signing, reboot, determinism -------------------------------------------------
def test_garbage_bytes_are_counted_and_ignored(make_rig):
    rig = make_rig()
    rig.client.write(b"\x00\x01garbage\xff" * 10)
    frame = bytearray(rig.client.mav.param_request_read_encode(1, 1, b"RC1_MIN", -1)
                      .pack(rig.client.mav))
    frame[-1] ^= 0xFF  # bad CRC
    rig.client.write(bytes(frame))
    rig.client.write(b"\xfd\x05")  # a truncated frame
    rig.run(0.1)
    assert rig.sim.counters.bad_data >= 2
    assert rig.param("RC1_MIN").param_value == 1100  # still answering


def test_signing_accepts_signed_and_ignores_unsigned(make_rig):
    rig = make_rig(signing_key=KEY)
    rig.clients.remove(rig.client)
    rig.client.close()
    rig.client = rig.connect(key=KEY)
    pv = rig.param("RC_OVERRIDE_TIME")
    assert pv is not None and pv.get_signed()  # answers are signed
    unsigned = rig.connect(sysid=255)
    wrong = rig.connect(sysid=255, key=hashlib.sha256(b"wrong").digest())
    for c in (unsigned, wrong):
        c.mav.param_set_send(1, 1, b"RC_OVERRIDE_TIME", 9.0, 9)
    rig.run(0.2)
    assert rig.sim.params["RC_OVERRIDE_TIME"] == 3.0
    assert rig.sim.counters.rejected_signature >= 2
    assert rig.set_param("RC_OVERRIDE_TIME", 7.0).param_value == 7.0


def test_signing_key_files(tmp_path):
    raw = tmp_path / "raw.key"
    raw.write_bytes(KEY)
    hexed = tmp_path / "hex.key"
    hexed.write_text(KEY.hex() + "\n")
    phrase = tmp_path / "phrase.key"
    phrase.write_text("my canal boat\n")
    assert load_signing_key(raw) == KEY and load_signing_key(hexed) == KEY
    assert load_signing_key(phrase) == hashlib.sha256(b"my canal boat").digest()
    empty = tmp_path / "empty.key"
    empty.write_text(" \n")
    with pytest.raises(InputError, match="empty"):
        load_signing_key(empty)
    with pytest.raises(InputError, match="no such"):
        load_signing_key(tmp_path / "missing.key")


def test_restart_resets_boot_time_and_state_not_the_boat(make_rig):
    rig = make_rig(ekf_delay_s=1.0)
    rig.arm()
    rig.override(ch3=1900)
    rig.run(2.0)
    att = rig.wait("ATTITUDE")
    assert att.time_boot_ms > 1900
    x_before = rig.sim.true_state
    rig.sim.restart()
    assert not rig.sim.armed and rig.sim.mode == ardupilot.MODES["INITIALISING"]  # starts up
    assert rig.sim.outputs == (0.0, 0.0)
    got = rig.run(0.5)
    assert [m.time_boot_ms for m in got if m.get_type() == "ATTITUDE"][0] < 100
    assert np.linalg.norm(rig.sim.true_state[:2] - x_before[:2]) < 1.5  # the boat kept going
    assert rig.sim.true_state[0] > 1.0
    ekf = [m.flags for m in got if m.get_type() == "EKF_STATUS_REPORT"]
    assert ekf and not any(f & EKF_POS_HORIZ_ABS for f in ekf)  # the EKF starts again
    assert not any(m.get_type() == "LOCAL_POSITION_NED" for m in got)
    # the reboot command does the same, refused while armed
    rig.arm()
    assert rig.command(CMD_REBOOT, 1).result == FAILED
    rig.command(CMD_ARM, 0)
    rig.run(1.0)
    assert rig.command(CMD_REBOOT, 1).result == ACCEPTED
    assert rig.wait("ATTITUDE").time_boot_ms < 300


def _positions(make_rig, seed):
    rig = make_rig(seed=seed, ekf_delay_s=0.5)
    rig.run(3.0)
    return [(m.time_boot_ms, m.x, m.y, m.vx, m.vy) for m in rig.client.inbox
            if m.get_type() == "LOCAL_POSITION_NED"]


def test_same_seed_same_messages(make_rig):
    a, b, c = _positions(make_rig, 3), _positions(make_rig, 3), _positions(make_rig, 4)
    assert len(a) >= 8 and a == b
    assert a != c


def test_state_messages_match_the_truth(make_rig):
    rig = make_rig(ekf_delay_s=0.5)
    org = rig.wait("GPS_GLOBAL_ORIGIN", timeout_s=1.0)  # sent when the EKF sets its origin
    lp = rig.wait("LOCAL_POSITION_NED", timeout_s=1.0)
    x_lp = rig.sim.true_state
    gp = rig.wait("GLOBAL_POSITION_INT", timeout_s=1.0)
    att = rig.wait("ATTITUDE", timeout_s=1.0)
    x = rig.sim.true_state
    # the EKF origin is where the boat was at the fix (0.5 s at 1 m/s from (0, 2)), and
    # LOCAL_POSITION_NED is measured from it
    n0, e0 = rig.sim.ekf_origin_ne
    assert n0 == pytest.approx(0.5, abs=0.7) and e0 == pytest.approx(2.0, abs=0.7)
    assert (org.latitude, org.longitude) == tuple(round(v * 1e7) for v in rig.sim.ekf_origin[:2])
    assert abs(lp.x - (x_lp[0] - n0)) < 0.3 and abs(lp.y - (x_lp[1] - e0)) < 0.3
    assert abs(lp.vx - x[3]) < 0.3
    lat0, lon0, alt0 = ardupilot.SITL_DEFAULT_HOME  # straight.toml has no origin
    north = math.radians(gp.lat * 1e-7 - lat0) * 6378137.0
    assert abs(north - x[0]) < 1.0 and gp.alt == round(alt0 * 1000) and gp.relative_alt == 0
    assert 0 <= gp.hdg < 36000 and abs(att.yaw - x[2]) < math.radians(2)
    assert abs(gp.vx - 100 * x[3]) < 30


# -- command line -----------------------------------------------------------------------------
def test_cli_serves_for_a_duration(capsys):
    port = free_udp_port()
    code = main(["autopilot-sim", "--listen", f"udpin:127.0.0.1:{port}", "--scenario",
                 str(STRAIGHT), "--speedup", "20", "--duration", "0.5", "--param", "RC1_MIN=1000"])
    assert code == 0
    assert "listening on udpin" in capsys.readouterr().out


def test_cli_bad_input_is_one_line(tmp_path, capsys):
    port = free_udp_port()
    args = ["autopilot-sim", "--listen", f"udpin:127.0.0.1:{port}", "--scenario"]
    assert main(args + [str(tmp_path / "nope.toml")]) == 2
    assert main(args + [str(STRAIGHT), "--param", "RC1_MIN"]) == 2
    assert main(args + [str(STRAIGHT), "--signing-key", str(tmp_path / "k")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 3


# -- the onboard DataFlash log ----------------------------------------------------------------
def _read_bin(path):
    from pymavlink import DFReader

    log = DFReader.DFReader_binary(str(path))
    out = {}
    while (m := log.recv_msg()) is not None:
        out.setdefault(m.get_type(), []).append(m)
    log.close()
    return out


def test_dataflash_log_as_ardupilot_writes_it(make_rig, tmp_path):
    from controller.pwm import CommandChannels

    rig = make_rig(init_s=1.0, ekf_delay_s=2.0, log_dir=tmp_path / "logs")
    rig.run(2.5)
    rig.arm()
    for _ in range(10):
        rig.override(ch3=1700, ch1=1400)  # 45 % ahead, steering below trim: nS > 0, port
        rig.run(0.3)
    path = rig.sim.log_paths[0]
    assert path.name == "00000001.BIN" and path.read_bytes()[:3] == b"\xa3\x95\x80"  # FMT first
    got = _read_bin(path)  # while it is being written: flushed as it goes
    assert {"FMT", "UNIT", "MULT", "FMTU", "PARM", "MODE", "ARM", "MSG", "ORGN", "XKF1", "ATT",
            "POS", "GPS", "IMU", "RCIN", "RCOU"} <= set(got)
    dz = [(m.TimeUS, m.Value) for m in got["PARM"] if m.Name == "RC1_DZ"]
    assert dz[0] == (0, 0.0) and dz[1][1] == 30.0 and dz[1][0] >= 1_000_000  # set by start-up
    assert [m.Mode for m in got["MODE"]][:2] == [16, 0]  # INITIALISING, then MANUAL
    assert got["ARM"][0].ArmState == 1
    assert got["ORGN"][0].Type == 0 and got["ORGN"][0].TimeUS >= 2_000_000
    xkf = got["XKF1"]
    rate = (len(xkf) - 1) / ((xkf[-1].TimeUS - xkf[0].TimeUS) * 1e-6)
    assert 24 <= rate <= 26 and xkf[0].TimeUS >= 2_000_000  # from the fix on, 25 Hz
    assert abs(xkf[0].PN) < 0.1 and xkf[-1].PN > 2.0  # metres from the EKF origin
    rcou = got["RCOU"]
    assert 49 <= (len(rcou) - 1) / ((rcou[-1].TimeUS - rcou[0].TimeUS) * 1e-6) <= 51
    params = {m.Name: m.Value for m in got["PARM"]}
    servos = CommandChannels.from_servo_params(params)
    nT, nS = servos.to_commands({1: rcou[-1].C1, 3: rcou[-1].C3})
    assert (nT, nS) == pytest.approx(rig.sim.outputs, abs=0.13)
    assert nT == pytest.approx(45.0, abs=0.2) and nS == pytest.approx(100 * 70 / 370, abs=0.3)
    assert rcou[-1].C2 == 0  # a disabled output
    assert got["RCIN"][-1].C3 == 1700 and got["RCIN"][-1].C1 == 1400
    assert got["IMU"][-1].GyrZ < 0  # turning to port
    rig.sim.restart()  # a reboot starts a new log
    rig.run(0.2)
    assert [p.name for p in rig.sim.log_paths] == ["00000001.BIN", "00000002.BIN"]
    assert (tmp_path / "logs" / "LASTLOG.TXT").read_text().strip() == "2"
