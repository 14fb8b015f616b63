"""The MAVLink link to an ArduPilot Rover autopilot: connection, heartbeats, signing, protocol.

`AutopilotLink` owns one pymavlink connection (MAVLink 2, ardupilotmega dialect). It
introduces itself as an onboard controller, locks onto the first autopilot it hears (or a
given system id) and ignores everyone else, rejects unsigned or badly signed messages when a
signing key is set, counts and skips garbage, and keeps the newest heartbeat, EKF state,
parameters and command acknowledgements. It measures the link delay with TIMESYNC (which
ArduPilot answers) and logs every message sent and received to a .tlog as it goes.

Times: every message is read as it arrives (the waits, `idle` included, wake on data with a
real clock) and keeps its arrival time; the autopilot's `time_boot_ms` is mapped to the
bridge's clock (`boot_clock`: TIMESYNC, checked against the arrivals), so a state's age is
the time since the autopilot made it, link delay included.

Nothing here blocks on the wall clock: `pump()` reads what is pending and returns, and every
wait loops over `pump()` and the clock, so a `VirtualClock` can run a simulated autopilot in
the same thread.
"""

from __future__ import annotations

import contextlib
import io

import math
import os
import re
import select
import statistics
import struct
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

from controller.errors import CanalnavError, InputError

from bridge.shared.ardupilot import MODE_NAMES, MODES, OVERRIDE_IGNORE, OVERRIDE_RELEASE
from bridge.onboard.boot_clock import BootClock
from bridge.shared.signing import counted_as_bad_data
from bridge.onboard.ekf_state import (EkfState, horizontal_position_ok, state_from_global,
                              state_from_local, predict_vector)
from controller.geodetic import geodetic_to_ned

os.environ["MAVLINK20"] = "1"  # before the dialect loads: MAVLink 2 (needed for signing)
from pymavlink import mavutil  # noqa: E402

mavutil.set_dialect("ardupilotmega")
mavlink = mavutil.mavlink

STREAM_MESSAGES = ("ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "EKF_STATUS_REPORT")
OVERRIDE_RELEASE_HIGH = 65534  # channels 9..18: UINT16_MAX - 1 hands the channel back
OVERRIDE_IGNORE_HIGH = 0  # channels 9..18: 0 (or UINT16_MAX) leaves the channel as it is
N_OVERRIDE_CHANNELS = 18
VEHICLE_TYPES_NOT_AUTOPILOT = {mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                               mavlink.MAV_TYPE_GIMBAL, mavlink.MAV_TYPE_ADSB}
MAX_MESSAGES_PER_PUMP = 5000  # a flood cannot starve the control loop for long
POLL_S = 0.01
POSITION_JUMP_M = 2.0  # the EKF's position moving this much more than its velocity says
POSITION_JUMP_WINDOW_S = 1.0  # ... between two positions at most this far apart in time
GLOBAL_STALE_MS = 1000  # LOCAL_POSITION_NED stands in when GLOBAL_POSITION_INT is this old
FRAME_TOLERANCE_M = 1.0  # LOCAL (from the EKF origin) and GLOBAL must agree this well
RC_PARAM = re.compile(r"^(RCMAP_[A-Z]+|RC\d+_[A-Z]+)$")  # what the RC mapping is made of


class LinkError(CanalnavError):
    """The autopilot did not answer, or refused; the message says what and how to fix it."""


@dataclass(frozen=True)
class Heartbeat:
    """The autopilot's newest HEARTBEAT, and when it arrived (bridge clock)."""

    system_id: int
    component_id: int
    type: int
    autopilot: int
    base_mode: int
    custom_mode: int
    system_status: int
    received_s: float

    @property
    def armed(self) -> bool:
        return bool(self.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

    @property
    def mode(self) -> str:
        return MODE_NAMES.get(self.custom_mode, f"mode {self.custom_mode}")


@dataclass(frozen=True)
class ParamChange:
    """A parameter whose PARAM_VALUE differs from the value the bridge knew (bridge clock)."""

    name: str
    old: float
    new: float
    received_s: float
    note: str = ""  # what the bridge did about it (e.g. the RC mapping it now uses)

    def describe(self) -> str:
        text = f"parameter {self.name} changed from {self.old:g} to {self.new:g}"
        return f"{text}: {self.note}" if self.note else text


@dataclass
class LinkCounters:
    """What the link saw; strangers, rejected signatures and garbage are skipped, not fatal."""

    received: int = 0  # accepted from the autopilot
    sent: int = 0
    ignored_other_source: int = 0  # valid messages from another system or component
    rejected_signature: int = 0  # unsigned or badly signed while signing is on
    bad_data: int = 0  # bytes that did not parse (garbage, CRC errors)
    autopilot_restarts: int = 0  # time_boot_ms went backwards
    frame_mismatches: int = 0  # LOCAL_POSITION_NED and GLOBAL_POSITION_INT disagreed
    clock_jumps: int = 0  # the autopilot's clock stalled or jumped (boot_clock re-anchored)
    position_jumps: int = 0  # the EKF's position jumped (a GPS glitch, an EKF reset)


def parse_url(url: str) -> tuple[str, int]:
    """pymavlink connection string and baud: `DEVICE,BAUD` (as MAVProxy) sets a serial baud."""
    if "," in url and ":" not in url.split(",", 1)[0]:
        device, baud = url.rsplit(",", 1)
        try:
            return device, int(baud)
        except ValueError:
            raise InputError(f"--connect {url!r}: baud {baud!r} is not a number") from None
    return url, 115200


class AutopilotLink:
    """One MAVLink connection to an ArduPilot Rover autopilot (see the module docstring)."""

    def __init__(self, url: str, clock, *, system_id: int = 255, component_id: int = 191,
                 target_system: int | None = None, signing_key: bytes | None = None,
                 tlog_path: str | Path | None = None, link_timeout_s: float = 3.0,
                 stale_s: float = 1.0, geodetic_origin=None, heartbeat_period_s: float = 1.0,
                 timesync_period_s: float = 1.0):
        for name, value, low, high in (("system id", system_id, 1, 255),
                                       ("component id", component_id, 1, 255)):
            if not low <= int(value) <= high:
                raise InputError(f"{name} {value} is outside {low}..{high}")
        if target_system is not None and not 1 <= int(target_system) <= 255:
            raise InputError(f"target system {target_system} is outside 1..255")
        if signing_key is not None and len(signing_key) != 32:
            raise InputError(f"signing key must be 32 bytes, got {len(signing_key)}")
        for name, value in (("link timeout", link_timeout_s), ("stale-after", stale_s)):
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be a positive number of seconds, got {value!r}")
        self.url = url
        self.clock = clock
        self.system_id = int(system_id)
        self.component_id = int(component_id)
        self.target_system = None if target_system is None else int(target_system)
        self.target_component: int | None = None
        self.link_timeout_s = float(link_timeout_s)
        self.stale_s = float(stale_s)
        self.geodetic_origin = geodetic_origin
        self.heartbeat_period_s = heartbeat_period_s
        self.timesync_period_s = timesync_period_s
        self.signing = signing_key is not None
        self.counters = LinkCounters()
        self.heartbeat: Heartbeat | None = None
        self.params: dict[str, float] = {}
        self.param_changes: deque[ParamChange] = deque(maxlen=100)  # for the loop to log
        self._fresh: set[str] = set()  # names answered since they were last asked for
        self._absent: set[str] = set()  # optional names this firmware did not answer
        self.ekf_flags: int | None = None
        self.rc_mapping = None  # controller.pwm.CommandChannels, set once the RC parameters are known
        self.last_pwm: dict[int, int] = {}
        self.statustexts: deque[tuple[float, int, str]] = deque(maxlen=20)  # from the autopilot
        self._state: EkfState | None = None
        self._attitude = None  # (message, received_s)
        self._position = None  # (source, message, received_s)
        self._local = self._global = None  # the newest of each, (message, received_s)
        self.ekf_origin = None  # (lat_deg, lon_deg, alt_m) from GPS_GLOBAL_ORIGIN
        self._ekf_offset = None  # the EKF origin in the scenario's frame (north, east m)
        self.position_source = None  # the message the state's position comes from
        self.frame_mismatch_m = None  # newest LOCAL vs GLOBAL comparison
        self.notices: deque[tuple[float, str]] = deque(maxlen=100)  # for the loop to log
        self.jumps_ne = (0.0, 0.0)  # (north, east) m: the sum of the position's jumps
        self.servo_outputs: deque[tuple[float, tuple[int, ...]]] = deque(maxlen=400)
        self._last_rx_s: float | None = None
        self._last_boot_ms: int | None = None
        self._acks: list[tuple[int, int, float]] = []  # (command, result, received_s)
        self._hb_due = -math.inf
        self._ts_due = -math.inf
        self._timesync_pending: dict[int, float] = {}
        self.boot_clock = BootClock()  # the autopilot's time since boot -> our clock
        self._ack_delays: deque[float] = deque(maxlen=9)
        self._statustext_id = 0
        self._epoch_us = int(time.time() * 1e6) - int(clock.now() * 1e6)
        self._tlog = None
        self._conn = self._open(url)
        if signing_key is not None:
            self._conn.setup_signing(bytes(signing_key), sign_outgoing=True,
                                     allow_unsigned_callback=lambda mav, msg_id: False)
        self._conn.mav.set_send_callback(self._on_send)
        if tlog_path is not None:
            try:
                self._tlog = open(tlog_path, "wb")
            except OSError as exc:
                self.close()
                raise InputError(f"cannot write the tlog {tlog_path}: {exc.strerror}") from None

    def _open(self, url: str):
        device, baud = parse_url(url)
        chatter = io.StringIO()  # pymavlink prints each refused try ("... sleeping")
        try:
            with contextlib.redirect_stdout(chatter):
                conn = mavutil.mavlink_connection(
                    device, baud=baud, source_system=self.system_id,
                    source_component=self.component_id, dialect="ardupilotmega",
                    autoreconnect=True)
        except Exception as exc:  # pymavlink raises anything from ValueError to SerialException
            tries = chatter.getvalue().count("sleeping")
            after = f" after {tries + 1} tries" if tries else ""
            raise InputError(f"cannot open the MAVLink connection {url!r}{after}: {exc} "
                             "(examples: udpin:0.0.0.0:14550, udpout:192.168.1.10:14550, "
                             "tcp:127.0.0.1:5760, /dev/ttyACM0,115200)") from None
        if not hasattr(conn, "mav") or not hasattr(conn, "write"):
            raise InputError(f"--connect {url!r} opens a log file, not a live link")
        return conn

    # -- receiving ---------------------------------------------------------------------------
    def pump(self) -> int:
        """Read every pending message (non-blocking), update the newest state, and send our
        heartbeat and timesync when due. Returns how many autopilot messages were accepted."""
        accepted = 0
        for _ in range(MAX_MESSAGES_PER_PUMP):
            try:
                msg = self._conn.recv_msg()
            except (OSError, mavlink.MAVError):
                msg = None
                self.counters.bad_data += 1
            if msg is None:
                if self._readable():
                    continue
                break
            accepted += self._handle(msg)
        self._send_periodic()
        return accepted

    def _readable(self) -> bool:
        fd = getattr(self._conn, "fd", None)
        if fd is None:
            return False
        try:
            return bool(select.select([fd], [], [], 0)[0])
        except (OSError, ValueError):
            return False

    def _handle(self, msg) -> int:
        if counted_as_bad_data(msg, self.counters):
            return 0
        kind = msg.get_type()
        self._log(msg.get_msgbuf(), sent=False)
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if self.target_component is None:
            if not (kind == "HEARTBEAT" and self._is_autopilot(msg, src[0])):
                self.counters.ignored_other_source += 1
                return 0
            self.target_system, self.target_component = src
        elif src != (self.target_system, self.target_component):
            self.counters.ignored_other_source += 1
            return 0
        now = self.clock.now()
        self._last_rx_s = now
        self.counters.received += 1
        boot_ms = getattr(msg, "time_boot_ms", None)
        self._check_restart(boot_ms)
        if boot_ms is not None:
            self.boot_clock.message(boot_ms * 1e-3, now)
        handler = getattr(self, f"_on_{kind.lower()}", None)
        if handler is not None:
            handler(msg, now)
        return 1

    def _is_autopilot(self, msg, system_id: int) -> bool:
        if self.target_system is not None and system_id != self.target_system:
            return False
        return (msg.type not in VEHICLE_TYPES_NOT_AUTOPILOT
                and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID)

    def _check_restart(self, boot_ms) -> None:
        if boot_ms is None:
            return
        if self._last_boot_ms is not None and boot_ms + 500 < self._last_boot_ms:
            self.counters.autopilot_restarts += 1
            self._state = self._attitude = self._position = None
            self._local = self._global = self._ekf_offset = self.ekf_origin = None
            self.boot_clock.reset()
            self.ekf_flags = None
        self._last_boot_ms = boot_ms

    def _on_heartbeat(self, msg, now: float) -> None:
        self.heartbeat = Heartbeat(msg.get_srcSystem(), msg.get_srcComponent(), msg.type,
                                   msg.autopilot, msg.base_mode, msg.custom_mode,
                                   msg.system_status, now)

    def _on_attitude(self, msg, now: float) -> None:
        self._attitude = (msg, now)

    # Frames. The scenario is placed on the Earth by `geodetic_origin` (its (0, 0)); positions
    # come from GLOBAL_POSITION_INT around it, or, while that is missing, from
    # LOCAL_POSITION_NED (metres from the EKF origin, wherever the first GPS fix came) moved
    # by where GPS_GLOBAL_ORIGIN puts the EKF origin. When both arrive they are compared.
    # Without a geodetic origin the state stays in the EKF's own local frame (link tests;
    # the onboard loop refuses to run that way).
    def _on_local_position_ned(self, msg, now: float) -> None:
        self._local = (msg, now)
        if self.geodetic_origin is None:
            self._use_position("LOCAL_POSITION_NED", msg, now)
            return
        self._check_frames()
        global_fresh = (self._global is not None
                        and msg.time_boot_ms - self._global[0].time_boot_ms <= GLOBAL_STALE_MS)
        if self._ekf_offset is not None and not global_fresh:
            self._use_position("LOCAL_POSITION_NED", msg, now)

    def _on_global_position_int(self, msg, now: float) -> None:
        if self.geodetic_origin is None:
            return
        self._global = (msg, now)
        self._check_frames()
        self._use_position("GLOBAL_POSITION_INT", msg, now)

    def _on_gps_global_origin(self, msg, now: float) -> None:
        origin = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
        if self.ekf_origin is not None and origin[:2] != self.ekf_origin[:2]:
            self.notices.append((now, f"EKF origin moved to {origin[0]:.7f}, {origin[1]:.7f} "
                                      f"(was {self.ekf_origin[0]:.7f}, {self.ekf_origin[1]:.7f})"))
        self.ekf_origin = origin
        self._ekf_offset = None
        if self.geodetic_origin is not None:
            self._ekf_offset = geodetic_to_ned(origin[0], origin[1], self.geodetic_origin)

    @property
    def ekf_origin_ne(self) -> tuple[float, float] | None:
        """Where GPS_GLOBAL_ORIGIN puts the EKF origin in the scenario's frame (m), or None."""
        return self._ekf_offset

    def _local_in_scenario(self, local) -> tuple[float, float]:
        dn, de = self._ekf_offset
        return float(local.x) + dn, float(local.y) + de

    def _check_frames(self) -> None:
        """Compare the newest LOCAL_POSITION_NED (moved by the EKF origin) with the newest
        GLOBAL_POSITION_INT, carried to the same autopilot time with the velocity."""
        if self._local is None or self._global is None or self._ekf_offset is None:
            return
        local, glob = self._local[0], self._global[0]
        dt = (local.time_boot_ms - glob.time_boot_ms) * 1e-3
        if abs(dt) > 0.2:
            return
        n, e = geodetic_to_ned(glob.lat * 1e-7, glob.lon * 1e-7, self.geodetic_origin)
        n, e = n + glob.vx * 0.01 * dt, e + glob.vy * 0.01 * dt
        ln, le = self._local_in_scenario(local)
        miss = math.hypot(ln - n, le - e)
        was_bad = self.frame_mismatch_m is not None and self.frame_mismatch_m > FRAME_TOLERANCE_M
        self.frame_mismatch_m = miss
        if miss > FRAME_TOLERANCE_M:
            self.counters.frame_mismatches += 1
            if not was_bad:
                self.notices.append((self._global[1], self.frame_disagreement()))

    def frame_disagreement(self) -> str:
        """What the two position messages say, when they disagree (for the console and log)."""
        local, glob = self._local[0], self._global[0]
        ln, le = self._local_in_scenario(local)
        n, e = geodetic_to_ned(glob.lat * 1e-7, glob.lon * 1e-7, self.geodetic_origin)
        lat, lon = self.ekf_origin[:2]
        return (f"LOCAL_POSITION_NED from the EKF origin {lat:.7f}, {lon:.7f} (GPS_GLOBAL_ORIGIN) "
                f"puts the boat at x {ln:.1f} y {le:.1f} m, GLOBAL_POSITION_INT at x {n:.1f} "
                f"y {e:.1f} m: {self.frame_mismatch_m:.1f} m apart")

    def _use_position(self, source: str, msg, now: float) -> None:
        self.position_source = source
        self._position = (source, msg, now)
        self._update_state()

    def _update_state(self) -> None:
        if self._attitude is None or self._position is None:
            return
        (att, t_att), (source, pos, t_pos) = self._attitude, self._position
        received = min(t_att, t_pos)
        before = self._state
        if source == "GLOBAL_POSITION_INT":
            self._state = state_from_global(att, pos, self.geodetic_origin, received)
        elif self.geodetic_origin is None:
            self._state = state_from_local(att, pos, received)
        else:
            self._state = state_from_local(att, pos, received, self._ekf_offset)
        self._check_jump(before, self._state, t_pos)

    def _check_jump(self, before, after, now: float) -> None:
        """A position that moved more than `POSITION_JUMP_M` from where the last one's
        velocity carried it (a GPS glitch the EKF took in, an EKF reset) is counted and said:
        the boat did not move so, and what was placed by the old position (walls, tracks,
        the water estimate's window) is that far off."""
        if before is None:
            return
        dt = after.time_boot_s - before.time_boot_s
        if not 0.0 < dt <= POSITION_JUMP_WINDOW_S:
            return
        expected = predict_vector(before.vector, dt)
        dn, de = after.x - expected[0], after.y - expected[1]
        if math.hypot(dn, de) > POSITION_JUMP_M:
            self.counters.position_jumps += 1
            self.jumps_ne = (self.jumps_ne[0] + dn, self.jumps_ne[1] + de)
            self.notices.append((now, f"the EKF's position jumped {math.hypot(dn, de):.1f} m "
                                      f"({dn:+.1f} m north, {de:+.1f} m east) between two "
                                      f"messages {dt:.2f} s apart: a GPS glitch or an EKF reset"))

    def _on_servo_output_raw(self, msg, now: float) -> None:
        """The autopilot's servo outputs 1-16 (us) at its time (s since boot)."""
        if int(getattr(msg, "port", 0)) != 0:
            return
        pwm = tuple(int(getattr(msg, f"servo{i}_raw", 0) or 0) for i in range(1, 17))
        t = msg.time_usec * 1e-6  # uint32 microseconds: wraps every 71.6 minutes
        if self._last_boot_ms is not None:
            wrap = 2 ** 32 * 1e-6
            t += round((self._last_boot_ms * 1e-3 - t) / wrap) * wrap
        self.servo_outputs.append((t, pwm))

    def _on_ekf_status_report(self, msg, now: float) -> None:
        self.ekf_flags = int(msg.flags)

    def _on_param_value(self, msg, now: float) -> None:
        """A parameter's value (an answer, or a change made by anyone: ArduPilot sends every
        change to all). A change is applied (the RC mapping follows its RCn_* and RCMAP_*)
        and queued in `param_changes` for the loop to log."""
        name = msg.param_id.decode() if isinstance(msg.param_id, bytes) else str(msg.param_id)
        name = name.split("\x00", 1)[0]
        value = float(msg.param_value)
        if not math.isfinite(value):
            self.counters.bad_data += 1
            return
        old = self.params.get(name)
        self.params[name] = value
        self._fresh.add(name)
        if old is not None and old != value:
            self.param_changes.append(ParamChange(name, old, value, now, self._follow(name)))

    def _follow(self, name: str) -> str:
        """Rebuild the RC mapping after a change to one of its parameters; what was done."""
        from controller.pwm import CommandChannels

        if self.rc_mapping is None or not RC_PARAM.match(name):
            return ""
        try:
            mapping = CommandChannels.from_rc_params(self.params)
        except (TypeError, ValueError) as exc:
            return f"not applied, the RC mapping would be invalid ({exc}); previous kept"
        if mapping == self.rc_mapping:
            return ""
        self.rc_mapping = mapping
        m = mapping
        return (f"RC mapping updated (steering RC{m.steering.channel} {m.steering.min}/"
                f"{m.steering.trim}/{m.steering.max} us dead zone {m.steering.dz}"
                f"{' reversed' if m.steering.reversed else ''}, throttle RC{m.throttle.channel} "
                f"{m.throttle.min}/{m.throttle.trim}/{m.throttle.max} us dead zone "
                f"{m.throttle.dz}{' reversed' if m.throttle.reversed else ''})")

    def pop_param_changes(self) -> list[ParamChange]:
        """The changes seen since the last call, oldest first."""
        out = list(self.param_changes)
        self.param_changes.clear()
        return out

    def _on_command_ack(self, msg, now: float) -> None:
        target = getattr(msg, "target_system", 0)
        if target in (0, self.system_id):
            self._acks.append((int(msg.command), int(msg.result), now))

    def _on_statustext(self, msg, now: float) -> None:
        text = msg.text.decode(errors="replace") if isinstance(msg.text, bytes) else str(msg.text)
        self.statustexts.append((now, int(msg.severity), text.rstrip("\x00")))

    def _on_timesync(self, msg, now: float) -> None:
        if msg.tc1 == 0:  # a request: answer with our clock, as ArduPilot does
            self._conn.mav.timesync_send(int(now * 1e9) + 1, msg.ts1)
            return
        sent = self._timesync_pending.pop(int(msg.ts1), None)
        if sent is not None:
            jumps = self.boot_clock.jumps
            self.boot_clock.timesync(sent, now, msg.tc1 * 1e-9)
            if self.boot_clock.jumps > jumps:
                self.counters.clock_jumps += 1
                step = self.boot_clock.last_jump_s
                self.notices.append((now, f"the autopilot's clock {'fell behind' if step > 0 else 'jumped ahead'} "
                                          f"by {abs(step) * 1e3:.0f} ms: its time mapping anchored again"))

    # -- state ---------------------------------------------------------------------------------
    @property
    def alive(self) -> bool:
        """A message from the autopilot arrived within `link_timeout_s` (bridge clock)."""
        return (self._last_rx_s is not None
                and self.clock.now() - self._last_rx_s <= self.link_timeout_s)

    @property
    def silence_s(self) -> float:
        """Time since the autopilot's last message (inf before the first)."""
        return math.inf if self._last_rx_s is None else self.clock.now() - self._last_rx_s

    @property
    def state(self) -> EkfState | None:
        """The newest EKF state (None before ATTITUDE and a position arrived)."""
        return self._state

    @property
    def state_age_s(self) -> float:
        """Age of the newest state on the bridge's clock: now less when the autopilot made
        it (its time_boot_ms mapped by `boot_clock`), so it includes the link's delay; inf if
        there is no state."""
        if self._state is None:
            return math.inf
        made = self.boot_clock.to_bridge(self._state.time_boot_s)
        if made is None:
            made = self._state.received_s
        return max(0.0, self.clock.now() - made)

    @property
    def state_fresh(self) -> bool:
        return self.state_age_s <= self.stale_s

    @property
    def horizontal_position_ok(self) -> bool:
        return self.ekf_flags is not None and horizontal_position_ok(self.ekf_flags)

    @property
    def link_delay_s(self) -> float:
        """One-way delay: half the median TIMESYNC round trip (else of the COMMAND_ACK round
        trips, which include the autopilot's handling); 0 before any was measured."""
        return self.boot_clock.delay_s

    # -- sending -------------------------------------------------------------------------------
    def _on_send(self, msg) -> None:
        self.counters.sent += 1
        self._log(msg.get_msgbuf(), sent=True)

    def _log(self, buf, sent: bool) -> None:
        """tlog record as MAVProxy writes it: big-endian uint64 microseconds since the epoch
        (the low two bits: 3 for sent, 0 for received), then the raw packet."""
        if self._tlog is None:
            return
        usec = (self._epoch_us + int(self.clock.now() * 1e6)) & ~3
        self._tlog.write(struct.pack(">Q", usec | (3 if sent else 0)) + bytes(buf))
        self._tlog.flush()

    def _send_periodic(self) -> None:
        now = self.clock.now()
        if now >= self._hb_due:
            self._hb_due = now + self.heartbeat_period_s
            self.send_heartbeat()
        if self.target_system is not None and now >= self._ts_due:
            self._ts_due = now + self.timesync_period_s
            ts1 = int(now * 1e9) * 256 + self.system_id  # unique, ours, never 0
            self._timesync_pending = {k: v for k, v in self._timesync_pending.items()
                                      if now - v < 10.0}
            self._timesync_pending[ts1] = now
            self._conn.mav.timesync_send(0, ts1)

    def send_heartbeat(self) -> None:
        """Our heartbeat: an onboard controller, not an autopilot."""
        self._conn.mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                      mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)

    def _target(self) -> tuple[int, int]:
        if self.target_system is None or self.target_component is None:
            raise LinkError("no autopilot heard yet: wait for its heartbeat first")
        return self.target_system, self.target_component

    def _override(self, values: dict[int, int], low: int, high: int) -> None:
        ts, tc = self._target()
        chans = [values.get(ch, low if ch <= 8 else high) for ch in range(1, N_OVERRIDE_CHANNELS + 1)]
        self._conn.mav.rc_channels_override_send(ts, tc, *chans)

    def send_commands(self, nT: float, nS: float) -> dict[int, int]:
        """Throttle and steering (percent; nS > 0 turns to port) as RC_CHANNELS_OVERRIDE on the
        mapped channels; every other channel is left alone. Returns the PWM by channel."""
        if self.rc_mapping is None:
            raise LinkError("the RC mapping is unknown: read the RC parameters first")
        pwm = self.rc_mapping.to_pwm(nT, nS)
        self._override(pwm, OVERRIDE_IGNORE, OVERRIDE_IGNORE_HIGH)
        self.last_pwm = dict(pwm)
        return pwm

    def send_neutral(self) -> dict[int, int]:
        """Throttle at trim (stop) and steering centred."""
        return self.send_commands(0.0, 0.0)

    def release(self) -> None:
        """Hand every overridden channel back to the RC receiver (0 on channels 1..8; UINT16_MAX-1
        on a mapped channel above 8, as the MAVLink spec and ArduPilot read it)."""
        high = {}
        if self.rc_mapping is not None:
            for cal in (self.rc_mapping.throttle, self.rc_mapping.steering):
                if cal.channel > 8:
                    high[cal.channel] = OVERRIDE_RELEASE_HIGH
        self._override(high, OVERRIDE_RELEASE, OVERRIDE_IGNORE_HIGH)
        self.last_pwm = {}

    def statustext(self, text: str, severity: int = mavlink.MAV_SEVERITY_WARNING) -> None:
        """A message for the ground station (chunked by 50 characters if longer, MAVLink 2)."""
        data = text.encode("utf-8", errors="replace")
        chunks = [data[i:i + 50] for i in range(0, len(data), 50)] or [b""]
        if len(chunks) == 1:
            self._conn.mav.statustext_send(severity, chunks[0])
            return
        self._statustext_id = self._statustext_id % 65535 + 1
        for seq, chunk in enumerate(chunks):
            self._conn.mav.statustext_send(severity, chunk, self._statustext_id, seq)

    # -- waiting -------------------------------------------------------------------------------
    def wait_until(self, predicate, timeout_s: float) -> bool:
        """Pump and sleep on the clock until `predicate()` holds (True) or the time is up."""
        deadline = self.clock.now() + timeout_s
        while True:
            self.pump()
            if predicate():
                return True
            remaining = deadline - self.clock.now()
            if remaining <= 0:
                return False
            self._wait(min(POLL_S, remaining))

    def idle(self, seconds: float) -> None:
        """Let `seconds` pass reading every message as it arrives (each keeps its arrival
        time): how the loop waits between control steps."""
        deadline = self.clock.now() + seconds
        while True:
            self.pump()
            remaining = deadline - self.clock.now()
            if remaining <= 1e-9:
                return
            self._wait(min(POLL_S, remaining))

    def _wait(self, seconds: float) -> None:
        """Sleep up to `seconds`, waking when the link has data (a real clock's select)."""
        fd = getattr(self._conn, "fd", None)
        wait = getattr(self.clock, "wait_readable", None)
        if wait is not None and isinstance(fd, int) and fd >= 0:
            wait(fd, seconds)
        else:
            self.clock.sleep(seconds)

    def wait_heartbeat(self, timeout_s: float = 30.0) -> Heartbeat:
        """Wait for a live autopilot heartbeat; it must come from a boat or a rover."""
        ok = self.wait_until(lambda: self.heartbeat is not None
                             and self.clock.now() - self.heartbeat.received_s <= self.link_timeout_s,
                             timeout_s)
        if not ok:
            whom = "an autopilot" if self.target_system is None else f"system {self.target_system}"
            raise LinkError(f"no heartbeat from {whom} on {self.url} within {timeout_s:g} s "
                            "(is the autopilot running? udpin listens, udpout sends first)")
        from bridge.onboard.preflight import vehicle_refusals

        refused = vehicle_refusals(self.heartbeat)
        if refused:
            raise LinkError(refused[0])
        return self.heartbeat

    def wait_past_startup(self, timeout_s: float = 60.0) -> Heartbeat:
        """Wait until the heartbeat says the autopilot is running: not MAV_STATE_UNINIT, BOOT
        or CALIBRATING, not in mode INITIALISING. ArduPilot answers MAVLink during its
        start-up but sets some parameters (Rover: the RC dead zones) only at its end."""
        from bridge.shared.ardupilot import MAV_STATE_STARTING, MODES

        def running() -> bool:
            hb = self.heartbeat
            return (hb is not None and hb.system_status not in MAV_STATE_STARTING
                    and hb.custom_mode != MODES["INITIALISING"]
                    and self.clock.now() - hb.received_s <= self.link_timeout_s)

        if not self.wait_until(running, timeout_s):
            hb = self.heartbeat
            state = ("no heartbeat" if hb is None else
                     f"HEARTBEAT system_status {MAV_STATE_STARTING.get(hb.system_status, hb.system_status)}"
                     f", mode {hb.mode}")
            raise LinkError(f"the autopilot is still starting up after {timeout_s:g} s ({state}); "
                            "ArduPilot sets some parameters (the RC dead zones) only at the end "
                            "of its start-up, so the bridge waits for it")
        return self.heartbeat

    def wait_ekf_origin(self, timeout_s: float = 5.0):
        """Ask for GPS_GLOBAL_ORIGIN (MAV_CMD_REQUEST_MESSAGE) until it comes; the EKF origin
        (lat, lon, alt), or None if it did not come within `timeout_s`."""
        deadline = self.clock.now() + timeout_s
        while self.ekf_origin is None and self.clock.now() < deadline:
            self.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE,
                              mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, timeout_s=0.5, retries=1)
            self.wait_until(lambda: self.ekf_origin is not None,
                            max(0.0, min(1.0, deadline - self.clock.now())))
        return self.ekf_origin

    def pop_notices(self) -> list[tuple[float, str]]:
        """What the link noticed about the frames since the last call (bridge time, text)."""
        out = list(self.notices)
        self.notices.clear()
        return out

    def wait_position_ok(self, timeout_s: float) -> EkfState:
        """Wait until the EKF reports a usable horizontal position and a fresh state exists."""
        if not self.wait_until(lambda: self.horizontal_position_ok and self.state_fresh, timeout_s):
            flags = "none received" if self.ekf_flags is None else f"0x{self.ekf_flags:04x}"
            raise LinkError(f"no usable horizontal position from the EKF within {timeout_s:g} s "
                            f"(EKF_STATUS_REPORT flags: {flags}; state age "
                            f"{self.state_age_s:.1f} s); a GPS fix takes tens of seconds after boot")
        return self._state

    # -- protocol helpers ----------------------------------------------------------------------
    def command_long(self, command: int, *params: float, timeout_s: float = 1.0,
                     retries: int = 3) -> int | None:
        """COMMAND_LONG with retries; returns the COMMAND_ACK result (None: no answer)."""
        ts, tc = self._target()
        p = (list(params) + [0.0] * 7)[:7]
        for attempt in range(max(1, retries)):
            start = len(self._acks)
            sent = self.clock.now()
            self._conn.mav.command_long_send(ts, tc, command, attempt, *p)
            found: list = []

            def answered() -> bool:
                for cmd, result, t in self._acks[start:]:
                    if cmd == command and result != mavlink.MAV_RESULT_IN_PROGRESS:
                        found.append((result, t))
                        return True
                return False

            if self.wait_until(answered, timeout_s):
                result, t = found[0]
                self._ack_delays.append(max(0.0, t - sent) / 2.0)
                self.boot_clock.fallback_delay_s = statistics.median(self._ack_delays)
                return result
        return None

    def request_streams(self, rate_hz: float = 20.0, messages=STREAM_MESSAGES) -> dict[str, int | None]:
        """MAV_CMD_SET_MESSAGE_INTERVAL for each message; result by name (None: unanswered).
        (ArduPilot's SRn_/MAVn_ stream-rate parameters are left alone.)"""
        interval_us = 1e6 / float(rate_hz)
        out = {}
        for name in messages:
            msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
            out[name] = self.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval_us)
        return out

    def fetch_params(self, names, *, optional=(), timeout_s: float = 1.0,
                     retries: int = 3) -> dict[str, float]:
        """PARAM_REQUEST_READ by name, retried; returns name -> value for those that answered.

        Either name of an alias in `ardupilot.PARAM_ALIASES` satisfies the other (firmware
        knows only one): both are asked, and the value is returned under both names.
        `optional` names are asked too but never waited for or retried alone.
        """
        from bridge.shared.ardupilot import PARAM_ALIASES

        groups = []
        for name in dict.fromkeys(names):
            alias = next((pair for pair in PARAM_ALIASES.values() if name in pair), (name,))
            if alias not in groups:
                groups.append(alias)
        extra = [n for n in optional if not any(n in g for g in groups) and n not in self._absent]

        fresh = self._fresh

        def missing():
            return [g for g in groups if not any(n in fresh for n in g)]

        for name in [n for g in groups for n in g] + extra:
            fresh.discard(name)  # read fresh values (the known ones stay, to see changes)
        for attempt in range(max(1, retries)):
            todo = missing()
            if not todo and attempt > 0:
                break
            ask = [n for g in todo for n in g] + ([n for n in extra if n not in fresh]
                                                 if attempt == 0 else [])
            ts, tc = self._target()
            for name in ask:
                self._conn.mav.param_request_read_send(ts, tc, name.encode(), -1)
            if self.wait_until(lambda: not missing(), timeout_s):
                self.wait_until(lambda: all(n in fresh for n in extra), min(0.2, timeout_s))
                break
        out = {}
        for g in groups:
            for n in g:
                if n in fresh:
                    out.update({alias: self.params[n] for alias in g})
                    break
        out.update({n: self.params[n] for n in extra if n in fresh})
        return out

    def wait_params_settled(self, names, *, optional=(), timeout_s: float = 10.0) -> dict[str, float]:
        """Read `names` (as `fetch_params`) until two reads in a row agree: values that are
        still being set (the end of a start-up, a ground station writing them) are not used."""
        deadline = self.clock.now() + timeout_s
        previous = self.fetch_params(names, optional=optional)
        self._absent.update(n for n in optional if n not in previous)
        while True:
            got = self.fetch_params(names, optional=optional)
            if got == previous:
                return got
            if self.clock.now() >= deadline:
                moving = sorted(n for n in set(got) | set(previous) if got.get(n) != previous.get(n))
                raise LinkError(f"parameters still changing after {timeout_s:g} s: "
                                + ", ".join(f"{n} {previous.get(n)} -> {got.get(n)}" for n in moving))
            previous = got

    def _refusal(self, what: str, result: int | None) -> LinkError:
        if result is None:
            return LinkError(f"no answer to {what} after retries (link lost?)")
        name = mavlink.enums["MAV_RESULT"].get(result)
        label = name.name if name is not None else str(result)
        recent = [t for s, _, t in self.statustexts if self.clock.now() - s < 3.0]
        tail = f": {'; '.join(recent[-3:])}" if recent else ""
        return LinkError(f"the autopilot refused {what} ({label}){tail}")

    def arm(self, timeout_s: float = 2.0) -> None:
        """Arm (MAV_CMD_COMPONENT_ARM_DISARM); raises LinkError with the reason if refused."""
        result = self.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout_s=timeout_s)
        if result != mavlink.MAV_RESULT_ACCEPTED:
            raise self._refusal("to arm", result)

    def set_mode(self, name: str, timeout_s: float = 1.0, retries: int = 3) -> None:
        """Switch to a Rover mode by name (MAV_CMD_DO_SET_MODE, custom mode)."""
        key = name.upper()
        if key not in MODES:
            raise InputError(f"mode {name!r} is not a Rover mode (one of {', '.join(MODES)})")
        result = self.command_long(mavlink.MAV_CMD_DO_SET_MODE,
                                   mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, MODES[key],
                                   timeout_s=timeout_s, retries=retries)
        if result != mavlink.MAV_RESULT_ACCEPTED:
            raise self._refusal(f"mode {key}", result)

    def close(self) -> None:
        try:
            self._conn.close()
        except Exception:  # noqa: BLE001 - closing a dead socket is not an error
            pass
        if self._tlog is not None:
            self._tlog.close()
            self._tlog = None
