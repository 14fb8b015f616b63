"""A minimal scripted fake autopilot for the bridge's link and loop tests (not AutopilotSim).

It listens on a free loopback UDP port, runs as a VirtualClock peer in the test's thread,
answers heartbeats, PARAM_REQUEST_READ from a dict, COMMAND_LONG with COMMAND_ACK (and
REQUEST_MESSAGE for GPS_GLOBAL_ORIGIN), TIMESYNC, streams ATTITUDE / LOCAL_POSITION_NED / GLOBAL_POSITION_INT / EKF_STATUS_REPORT at
the rates asked, moves its boat with constant body velocities, and records every message it
receives with the virtual time, so tests can decode what the bridge sent and in what order.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import bridge.onboard.link  # noqa: F401 - sets MAVLink 2 before any connection is made
from bridge.shared.ardupilot import DEFAULT_PARAMS, MODE_NAMES, MODES
from bridge.shared.clock import VirtualClock
from controller.geodetic import ned_to_geodetic
from bridge.autopilot_sim.plant import free_udp_port
from pymavlink import mavutil

EKF_GOOD = 1 | 2 | 4 | 8 | 16 | 32


class FakeAutopilot:
    """A scripted ArduPilot Rover stand-in; switch behaviours with its attributes."""

    def __init__(self, clock, *, system_id=1, component_id=1, params=None, mode="MANUAL",
                 armed=False, vehicle_type=11, signing_key=None, state=(0, 0, 0, 2.0, 0, 0),
                 geodetic_origin=(52.0, 4.0, 0.0), ekf_flags=EKF_GOOD, sign=True):
        self.clock = clock
        self.port = free_udp_port()
        self.url = f"udpout:127.0.0.1:{self.port}"
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.port}", source_system=system_id,
                                               source_component=component_id, dialect="ardupilotmega")
        if signing_key is not None:
            self.conn.setup_signing(signing_key, sign_outgoing=sign,
                                    allow_unsigned_callback=lambda mav, msg_id: False)
        self.mav = self.conn.mav
        self.params = {**DEFAULT_PARAMS, **(params or {})}
        self.mode = MODES[mode]
        self.armed = armed
        self.vehicle_type = vehicle_type
        self.state = np.array(state, float)
        self.origin = geodetic_origin
        self.ekf_origin = geodetic_origin  # what GPS_GLOBAL_ORIGIN says (the local frame's 0)
        self.ekf_flags = ekf_flags
        self.intervals: dict[int, float] = {}  # message id -> period (s)
        self.due: dict[int, float] = {}
        self.received: list[tuple[float, object]] = []
        self.ack_results: dict[int, int] = {}  # command -> forced result
        self.mute = False  # sends nothing (the link cut towards the bridge)
        self.deaf = False  # ignores what it receives (records nothing, answers nothing)
        self.send_state = True  # ATTITUDE and positions (False: only heartbeats and EKF status)
        self.answer_timesync = True
        self.boot_t = 0.0
        self._hb_due = 0.0
        self._last = 0.0
        clock.add_peer(self.pump)

    # -- the peer ------------------------------------------------------------------------------
    def pump(self, now: float) -> None:
        dt = now - self._last
        self._last = now
        x, y, psi, u, v, r = self.state
        self.state[0] += (u * math.cos(psi) - v * math.sin(psi)) * dt
        self.state[1] += (u * math.sin(psi) + v * math.cos(psi)) * dt
        self.state[2] += r * dt
        while True:
            msg = self.conn.recv_msg()
            if msg is None:
                break
            if self.deaf or msg.get_type() == "BAD_DATA":
                continue
            self.received.append((now, msg))
            self._handle(msg)
        if self.mute:
            return
        if now >= self._hb_due:
            self._hb_due = now + 1.0
            base = mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            if self.armed:
                base |= mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
            self.mav.heartbeat_send(self.vehicle_type, mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                    base, self.mode, mavutil.mavlink.MAV_STATE_ACTIVE)
        for msg_id, period in self.intervals.items():
            if now + 1e-9 >= self.due.get(msg_id, 0.0):
                self.due[msg_id] = now + period
                self._send_stream(msg_id, now)

    def _send_stream(self, msg_id: int, now: float) -> None:
        m = mavutil.mavlink
        ms = int(round((now - self.boot_t) * 1000))
        x, y, psi, u, v, r = self.state
        vn, ve = u * math.cos(psi) - v * math.sin(psi), u * math.sin(psi) + v * math.cos(psi)
        if msg_id == m.MAVLINK_MSG_ID_EKF_STATUS_REPORT:
            self.mav.ekf_status_report_send(self.ekf_flags, 0.1, 0.1, 0.1, 0.1, 0.1)
        elif not self.send_state:
            return
        elif msg_id == m.MAVLINK_MSG_ID_ATTITUDE:
            self.mav.attitude_send(ms, 0.0, 0.0, math.atan2(math.sin(psi), math.cos(psi)), 0.0, 0.0, r)
        elif msg_id == m.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            self.mav.local_position_ned_send(ms, x, y, 0.0, vn, ve, 0.0)
        elif msg_id == m.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            lat, lon = ned_to_geodetic(x, y, self.origin)
            self.mav.global_position_int_send(ms, int(round(lat * 1e7)), int(round(lon * 1e7)), 0, 0,
                                              int(round(vn * 100)), int(round(ve * 100)), 0,
                                              int(math.degrees(psi) % 360 * 100))

    def _handle(self, msg) -> None:
        m = mavutil.mavlink
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_READ" and not self.mute:
            name = msg.param_id
            if name in self.params:
                self.mav.param_value_send(name.encode(), float(self.params[name]),
                                          m.MAV_PARAM_TYPE_REAL32, len(self.params), 0)
        elif kind == "TIMESYNC" and msg.tc1 == 0 and self.answer_timesync and not self.mute:
            # as ArduPilot: its time since boot, the clock of time_boot_ms
            self.mav.timesync_send(int((self.clock.now() - self.boot_t) * 1e9) + 1, msg.ts1)
        elif kind == "COMMAND_LONG":
            result = self.ack_results.get(msg.command, m.MAV_RESULT_ACCEPTED)
            if result == m.MAV_RESULT_ACCEPTED:
                if msg.command == m.MAV_CMD_SET_MESSAGE_INTERVAL:
                    self.intervals[int(msg.param1)] = msg.param2 * 1e-6
                elif msg.command == m.MAV_CMD_DO_SET_MODE:
                    self.mode = int(msg.param2)
                elif msg.command == m.MAV_CMD_COMPONENT_ARM_DISARM:
                    self.armed = msg.param1 == 1
                elif (msg.command == m.MAV_CMD_REQUEST_MESSAGE and int(msg.param1) == 49
                      and not self.mute and self.ekf_origin is not None):
                    lat, lon, alt = self.ekf_origin
                    self.mav.gps_global_origin_send(int(round(lat * 1e7)), int(round(lon * 1e7)),
                                                    int(round(alt * 1000)), 0)
            if not self.mute:
                self.mav.command_ack_send(msg.command, result, 0, 0, msg.get_srcSystem(),
                                          msg.get_srcComponent())

    # -- what the tests look at ----------------------------------------------------------------
    @property
    def mode_name(self) -> str:
        return MODE_NAMES[self.mode]

    def messages(self, kind: str | None = None) -> list:
        return [msg for _, msg in self.received if kind is None or msg.get_type() == kind]

    def overrides(self) -> list[list[int]]:
        """Channels 1..18 of each RC_CHANNELS_OVERRIDE received, in order."""
        return [[getattr(o, f"chan{i}_raw") for i in range(1, 19)]
                for o in self.messages("RC_CHANNELS_OVERRIDE")]

    def restart(self) -> None:
        """A reboot: boot time restarts, requested rates are forgotten."""
        self.boot_t = self.clock.now()
        self.intervals.clear()
        self.due.clear()

    def close(self) -> None:
        self.conn.close()


@pytest.fixture
def vclock():
    return VirtualClock(0.01)


@pytest.fixture
def make_autopilot(vclock):
    """Factory: FakeAutopilot(vclock, **kwargs), closed after the test."""
    made = []

    def make(**kwargs):
        ap = FakeAutopilot(vclock, **kwargs)
        made.append(ap)
        return ap

    yield make
    for ap in made:
        ap.close()


@pytest.fixture
def udp_port():
    return free_udp_port


@pytest.fixture
def sim_rig(tmp_path):
    """Factory: `kind(scenario, tmp_path / "rigN", **kwargs)`, a `SimRig` of tests/bridge/rigs.py
    unless told otherwise, every rig made closed after the test."""
    from .rigs import SimRig

    made = []

    def make(scenario, kind=SimRig, **kwargs):
        rig = kind(scenario, tmp_path / f"rig{len(made)}", **kwargs)
        made.append(rig)
        return rig

    yield make
    for rig in made:
        rig.close()
