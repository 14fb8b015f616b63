"""A simulated ArduPilot Rover (boat frame) speaking MAVLink 2, with the boat FMU as its physics.

What is simulated, as ArduPilot Rover does it:
- Start-up: for `init_s` seconds after (re)boot the mode is INITIALISING and the heartbeat's
  system_status MAV_STATE_CALIBRATING; MAVLink answers meanwhile, but arming and mode changes
  are refused, and the steering and throttle dead zones read 0 until start-up ends and sets
  them to 30 us (unless stored: `Rover::init_rc_in`). Then MANUAL, disarmed.
- HEARTBEAT (MAV_TYPE_SURFACE_BOAT, MAV_AUTOPILOT_ARDUPILOTMEGA, custom_mode = Rover mode
  number, SAFETY_ARMED when armed; system_status STANDBY in HOLD, ACTIVE otherwise, as
  `GCS_MAVLINK_Rover::vehicle_system_status`).
- A parameter that changes (PARAM_SET from any ground station, `set_param`) is sent to all as
  PARAM_VALUE; start-up's own defaults are not (ArduPilot's `set_default` does not notify).
- Parameters (PARAM_REQUEST_READ by name or index, PARAM_REQUEST_LIST, PARAM_SET; REAL32;
  unknown names ignored silently), names of 4.7 or, with `legacy_param_names`, of 4.5.
- Commands, each ACKed: COMPONENT_ARM_DISARM (21196 forces), DO_SET_MODE, SET/GET_MESSAGE_
  INTERVAL, REQUEST_MESSAGE, REQUEST_AUTOPILOT_CAPABILITIES, PREFLIGHT_REBOOT_SHUTDOWN
  (param1 = 1, refused while armed); any other command is MAV_RESULT_UNSUPPORTED. The SET_MODE
  message is answered with a COMMAND_ACK for command 11, as ArduPilot does.
- RC_CHANNELS_OVERRIDE addressed to our system id from the GCS sysid (MAV_GCS_SYSID /
  SYSID_MYGCS) only, per-channel release/ignore values, RC_OPTIONS, RC_OVERRIDE_TIME
  (see `rc`). Any other message is answered whoever sends it, as ArduPilot does.
- Streams (defaults in `streams.DEFAULT_INTERVALS`): HEARTBEAT, SYS_STATUS and
  EKF_STATUS_REPORT at 1 Hz; ATTITUDE, LOCAL_POSITION_NED, GLOBAL_POSITION_INT at 4 Hz;
  RC_CHANNELS and SERVO_OUTPUT_RAW off. A reboot forgets requested rates.
- The EKF (`ekf`): attitude only until `ekf_delay_s` after boot (the first GPS
  fix; never before start-up is over), then position and velocity; LOCAL_POSITION_NED and
  GLOBAL_POSITION_INT are sent only once the position is valid. The scenario's (0, 0) is on
  the Earth at its `[origin]` (else at ArduPilot SITL's default home, as SITL puts it);
  GLOBAL_POSITION_INT is there. The EKF origin is set at the first fix wherever the boat is
  then (moving or not), and LOCAL_POSITION_NED is measured from it; GPS_GLOBAL_ORIGIN says
  where it is (sent when set, on request, or as a stream). A reboot forgets it.
- TIMESYNC requests are answered; the legacy REQUEST_DATA_STREAM sets a group's rate
  (EXTENDED_STATUS: SYS_STATUS; RC_CHANNELS: RC_CHANNELS, SERVO_OUTPUT_RAW; POSITION:
  GLOBAL_POSITION_INT, LOCAL_POSITION_NED; EXTRA1: ATTITUDE; EXTRA3: EKF_STATUS_REPORT).
- Signing: with a key, unsigned or badly signed messages are dropped (except RADIO_STATUS
  and RADIO, as ArduPilot), and everything sent is signed.

Simplified, on purpose:
- Outputs: MANUAL and armed maps the steering and throttle channels (RCMAP_ROLL,
  RCMAP_THROTTLE, RCn_* calibration) to (nT, nS). Disarmed gives throttle 0 *and* steering 0
  (ArduPilot keeps steering live when disarmed); HOLD gives 0, 0; every other mode is not
  simulated and gives neutral outputs.
- Arming has one pre-arm check, the position estimate (Rover's "Need Position Estimate",
  under the GPS bit), run in every mode (ArduPilot runs it only in modes needing position).
  ARMING_SKIPCHK: skipped if bit 3 is set (-1 sets every bit). Legacy ARMING_CHECK: run if
  bit 0 (all) or bit 3 is set; 0 runs none. Modes needing position or velocity (AUTO,
  GUIDED, ...) are refused until the EKF is ready; INITIALISING cannot be selected.
- An invalid RC calibration set at run time is stored but the previous mapping is kept
  (a STATUSTEXT says so); SYSID_THISMAV takes effect at the next reboot.
- The receiver is always at trim (neutral); no failsafes, missions or battery model.

Time: the physics runs on the clock, in whole `physics_step_s` steps from the clock time at
construction; `time_boot_ms` counts from the last (re)boot on the same time base.
"""

from __future__ import annotations

import math
import select
from collections import deque
from dataclasses import dataclass

import numpy as np

from controller.errors import InputError

from bridge.shared import ardupilot
from . import streams as st
from .ekf import EkfModel
from controller.geodetic import geodetic_to_ned, ned_to_geodetic  # both ends agree
from .params import ParamTable, param_id
from .rc import UINT16_MAX, RcInput
from controller.pwm import CommandChannels
from bridge.shared.boat_physics import BoatPhysics
from bridge.shared.signing import counted_as_bad_data

COMPONENT_ID = 1  # MAV_COMP_ID_AUTOPILOT1
PARAMS_PER_PUMP = 20  # PARAM_REQUEST_LIST answers are spread over pumps, as ArduPilot's queue
MAX_MESSAGES_PER_PUMP = 1000  # a flood cannot stall the physics for ever
UNSIGNED_ALLOWED = (109, 166)  # RADIO_STATUS, RADIO: ArduPilot accepts them unsigned
FIRMWARE = {False: (4, 7, 0), True: (4, 5, 7)}  # version announced, by legacy_param_names

MANUAL = ardupilot.MODES["MANUAL"]
HOLD = ardupilot.MODES["HOLD"]
INITIALISING = ardupilot.MODES["INITIALISING"]
NEEDS_ESTIMATE = {ardupilot.MODES[m] for m in (
    "ACRO", "STEERING", "LOITER", "FOLLOW", "DOCK", "CIRCLE", "AUTO", "RTL", "SMART_RTL", "GUIDED")}
MANUAL_INPUT_MODES = {ardupilot.MODES[m] for m in ("MANUAL", "ACRO", "STEERING")}


def _mavlink2():
    from pymavlink.dialects.v20 import ardupilotmega

    return ardupilotmega


def open_connection(url: str, system_id: int, component_id: int = COMPONENT_ID):
    """A pymavlink connection that speaks MAVLink 2 whatever the MAVLINK20 environment says."""
    from pymavlink import mavutil

    try:
        conn = mavutil.mavlink_connection(url, source_system=system_id,
                                          source_component=component_id)
    except (OSError, ValueError) as exc:
        raise InputError(f"{url}: cannot open the MAVLink connection: {exc}") from None
    # Replace the parser/encoder by the MAVLink 2 dialect (mavutil picks MAVLink 1 unless
    # MAVLINK20 is set process-wide); pymavlink's own auto-switch does the same thing.
    conn.mav = _mavlink2().MAVLink(conn, srcSystem=system_id, srcComponent=component_id)
    conn.mav.robust_parsing = True
    conn.WIRE_PROTOCOL_VERSION = "2.0"
    conn.first_byte = False
    return conn


def _is_datagram(conn) -> bool:
    from pymavlink import mavutil

    return isinstance(conn, (mavutil.mavudp, mavutil.mavmcast))


@dataclass
class LinkCounters:
    """What arrived and what was dropped (tests and diagnostics)."""

    messages: int = 0
    bad_data: int = 0  # garbage, bad CRC, cut-short frames
    rejected_signature: int = 0  # unsigned or badly signed while signing is on
    bad_fields: int = 0  # well-formed messages whose fields made no sense (NaN, ...)
    overrides_ignored: int = 0  # RC_CHANNELS_OVERRIDE not obeyed (sysid, target, RC_OPTIONS)


def _int(x, default: int = 0) -> int:
    """A message field as an int; NaN or infinite gives `default`."""
    try:
        return int(round(float(x)))
    except (TypeError, ValueError, OverflowError):
        return default


def clock_faults_checked(faults) -> list:
    """(at_s, step_s) pairs in time order: at `at_s` (clock seconds after start) the
    autopilot stalls for `step_s` and runs that far behind from then on; a negative step
    jumps its clock ahead (the physics catches up at once)."""
    out = []
    for item in faults:
        try:
            at, step = (float(v) for v in item)
        except (TypeError, ValueError):
            raise InputError(f"clock fault {item!r}: expected (at_s, step_s) numbers") from None
        if not (math.isfinite(at) and at >= 0 and math.isfinite(step) and step != 0):
            raise InputError(f"clock fault {item!r}: at_s >= 0 and a non-zero finite step_s "
                             "needed")
        out.append((at, step))
    return sorted(out)


class AutopilotSim:
    """The simulated autopilot on one MAVLink connection; drive it with `pump(now)`."""

    def __init__(self, scenario, url: str, clock, *, seed: int = 0,
                 signing_key: bytes | None = None, params: dict | None = None,
                 ekf_delay_s: float = 20.0, legacy_param_names: bool = False,
                 work_dir=None, physics_step_s: float = 0.01, system_id: int = 1,
                 init_s: float = 3.0, log_dir=None, ekf_noise=None, clock_faults=()):
        if not physics_step_s > 0:
            raise InputError(f"physics step must be positive, got {physics_step_s}")
        if not (math.isfinite(init_s) and init_s >= 0):
            raise InputError(f"start-up time must be 0 or more seconds, got {init_s}")
        self.init_s = float(init_s)
        if not 1 <= int(system_id) <= 255:
            raise InputError(f"system id must be 1..255, got {system_id}")
        self.scenario = scenario
        self.clock = clock
        self.physics_step_s = float(physics_step_s)
        self._sysid = int(system_id)
        self._params = ParamTable(self._sysid, legacy_param_names, params)
        self._mapping = self._build_mapping()
        self._servos = self._build_servos()
        self._origin = scenario.geodetic_origin or ardupilot.SITL_DEFAULT_HOME
        self.ekf_origin = None  # (lat_deg, lon_deg, alt_m), set at the first GPS fix
        self._ekf = EkfModel(seed, ekf_delay_s, *(() if ekf_noise is None else (ekf_noise,)))
        self._rc = RcInput()
        self._streams = st.Streams()
        self.counters = LinkCounters()
        self.received_statustext: list[str] = []
        self._physics = None
        self._conn = None
        self._log = None
        try:
            self._physics = BoatPhysics(scenario, work_dir, tmp_prefix="canalnav-autopilot-")
            self._conn = open_connection(url, self._sysid)
            self._datagrams = _is_datagram(self._conn)
            if signing_key is not None:
                self._setup_signing(signing_key)
        except BaseException:
            self.close()
            raise
        self._t0 = self._start = clock.now()
        self._clock_faults = clock_faults_checked(clock_faults)
        self._steps = 0
        self._outputs = (0.0, 0.0)
        if log_dir is not None:
            from .log import AutopilotLog

            self._log = AutopilotLog(log_dir)
        self._boot(0.0)

    # -- construction ---------------------------------------------------------------------
    def _build_servos(self) -> CommandChannels:
        try:
            return CommandChannels.from_servo_params(self._params.values)
        except ValueError as exc:
            raise InputError(f"autopilot parameters: {exc}") from None

    def _build_mapping(self) -> CommandChannels:
        try:
            return CommandChannels.from_rc_params(self._params.values)
        except ValueError as exc:
            raise InputError(f"autopilot parameters: {exc}") from None

    def _setup_signing(self, key: bytes) -> None:
        key = bytes(key)
        if len(key) != 32:
            raise InputError(f"a MAVLink signing key has 32 bytes, got {len(key)}")
        self._conn.setup_signing(key, sign_outgoing=True,
                                 allow_unsigned_callback=lambda mav, msg_id: msg_id in UNSIGNED_ALLOWED)

    def _boot(self, boot_t: float) -> None:
        """Power-on state: starting up (INITIALISING), disarmed, no overrides, default
        streams, EKF not ready, start-up's parameter values."""
        self._boot_t = boot_t
        self.armed = False
        self.mode = INITIALISING
        self._initialised = False
        self.ekf_origin = None
        self._params.boot()
        self._mapping = self._build_mapping()
        self._rc.clear()
        self._streams.reset(0.0)
        self._param_queue: deque[int] = deque()
        self._oneshot: list[int] = []
        self._reboot_pending = False
        self._outputs = (0.0, 0.0)
        if self._log is not None:
            self._log.start(self)
        major, minor, patch = FIRMWARE[self._params.legacy]
        self._statustext(f"ArduRover V{major}.{minor}.{patch} (canalnav simulator)",
                         severity=6)

    # -- public state -----------------------------------------------------------------------
    @property
    def last_plant_output(self):
        """The boat's last step (scenarios.plants.plant.PlantOutput: the truth)."""
        return self._physics.output

    @property
    def true_state(self) -> np.ndarray:
        return self.last_plant_output.state.copy()

    @property
    def actuators(self) -> np.ndarray:
        return self.last_plant_output.actuators.copy()

    @property
    def outputs(self) -> tuple[float, float]:
        return self._outputs

    @property
    def time_s(self) -> float:
        return self._steps * self.physics_step_s

    @property
    def boot_s(self) -> float:
        """Seconds since the last (re)boot: time_boot_ms / 1000."""
        return self.time_s - self._boot_t

    def boot_to_clock(self, time_boot_s: float) -> float:
        """The clock time at which this autopilot's time since boot was `time_boot_s` (what
        a message stamped with it describes): for tests of the bridge's time keeping."""
        return self._t0 + self._boot_t + float(time_boot_s)

    @property
    def params(self) -> dict:
        return dict(self._params.values)

    @property
    def param_defaults(self) -> dict:
        return self._params.defaults

    @property
    def log_paths(self) -> list:
        """The DataFlash logs written so far (one per boot), oldest first."""
        return [] if self._log is None else list(self._log.paths)

    def rc_inputs(self, n: int = 14) -> list[int]:
        """RC input channels 1..n as the firmware reads them (overrides, else the receiver)."""
        return self._rc.channels(self._params, self.boot_s, n)

    def servo_outputs(self, n: int = 14) -> list[int]:
        """Servo outputs 1..n (us) for the firmware's (nT, nS): SERVOn_FUNCTION and
        SERVOn_* say which output and how; a disabled output is 0."""
        pwm = self._servos.to_pwm(*self._outputs)
        return [int(pwm.get(ch, 0)) for ch in range(1, n + 1)]

    @property
    def actuator_commands(self) -> tuple[float, float]:
        """(nT, nS) the servos carry out: the firmware's outputs through their PWM."""
        s = self._servos
        return s.to_commands(s.to_pwm(*self._outputs))

    @property
    def estimate(self):
        """The EKF's estimate now (ekf.Estimate, in the scenario's frame)."""
        return self._estimate()

    def geodetic_position(self, e) -> tuple[float, float]:
        """An estimate's latitude and longitude (degrees)."""
        return ned_to_geodetic(e.north_m, e.east_m, self._origin)

    def local_position(self, e) -> tuple[float, float]:
        """An estimate's north and east from the EKF origin (m), as LOCAL_POSITION_NED."""
        lat, lon = self.geodetic_position(e)
        return geodetic_to_ned(lat, lon, self.ekf_origin)

    @property
    def initialised(self) -> bool:
        """Start-up is over (the mode is no longer INITIALISING)."""
        return self._initialised

    @property
    def ekf_ready(self) -> bool:
        return self._initialised and self._ekf.ready(self.boot_s)

    @property
    def system_id(self) -> int:
        return self._sysid

    def set_param(self, name: str, value: float) -> bool:
        """Set a parameter as PARAM_SET would (no message sent); False if unknown."""
        ok = self._params.set(name, float(value))
        if ok:
            self._param_changed(name)
            if self._conn is not None:
                self._send_param(name)
        return ok

    # -- the loop -------------------------------------------------------------------------
    def pump(self, now: float) -> None:
        """Handle everything received, advance the physics to `now`, send what is due.

        `now` is clock time; the physics' time 0 is the clock's time at construction."""
        if self._conn is None:
            return
        if self._clock_faults and now - self._start >= self._clock_faults[0][0]:
            at, step = self._clock_faults[0]
            if step > 0 and now - self._start < at + step:
                return  # stalled, as SITL under load: nothing handled, stepped or sent
            self._clock_faults.pop(0)
            self._t0 += step  # its clock now runs `step` behind (< 0: ahead, caught up)
        if not self._initialised and self.boot_s >= self.init_s - 1e-9:
            self._finish_init()
        self._receive_all()
        if self._reboot_pending:
            self.restart()
        self._outputs = self._compute_outputs()
        self._advance(now - self._t0)
        self._outputs = self._compute_outputs()
        if self.ekf_origin is None and self.ekf_ready:
            self._set_ekf_origin()
        if self._log is not None:
            self._log.update(self)
        self._send_due()

    def serve(self, duration_s: float | None = None) -> None:
        """Pump on the clock until `duration_s` (clock seconds) has passed, or for ever."""
        start = self.clock.now()
        while duration_s is None or self.clock.now() - start < duration_s:
            self.pump(self.clock.now())
            self.clock.sleep(0.002)

    def _set_ekf_origin(self) -> None:
        """The first fix: the EKF origin is the estimated position now, moving or not."""
        e = self._estimate()
        lat, lon = ned_to_geodetic(e.north_m, e.east_m, self._origin)
        self.ekf_origin = (lat, lon, float(self._origin[2]))
        self._oneshot.append(st.GPS_GLOBAL_ORIGIN)
        if self._log is not None:
            self._log.origin(self)

    @property
    def ekf_origin_ne(self) -> tuple[float, float] | None:
        """The EKF origin in the scenario's frame (north, east metres), None before a fix."""
        if self.ekf_origin is None:
            return None
        return geodetic_to_ned(self.ekf_origin[0], self.ekf_origin[1], self._origin)

    def _finish_init(self) -> None:
        """The end of start-up: Rover's late defaults (dead zones), then MANUAL."""
        changed = self._params.finish_init()
        if changed:
            self._mapping = self._build_mapping()
        self._initialised = True
        self.mode = MANUAL
        if self._log is not None:
            for name in changed:
                self._log.param(self, name, self._params[name])
            self._log.mode(self, 1)  # ModeReason::INITIALISED
        self._statustext("Ready to drive", severity=6)

    def restart(self) -> None:
        """A reboot: boot time from 0, disarmed, MANUAL, EKF not ready; the boat keeps moving."""
        new_id = _int(self._params.get("SYSID_THISMAV"), self._sysid)
        if 1 <= new_id <= 255 and new_id != self._sysid and self._conn is not None:
            self._sysid = new_id
            self._conn.mav.srcSystem = new_id
        self._boot(self.time_s)

    def close(self) -> None:
        if self._conn is not None:
            try:
                self._conn.close()
            except OSError:
                pass
            self._conn = None
        if self._physics is not None:
            self._physics.close()
            self._physics = None
        if self._log is not None:
            self._log.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- physics ---------------------------------------------------------------------------
    def _advance(self, t_target: float) -> None:
        n = math.floor(t_target / self.physics_step_s + 1e-6)
        while self._steps < n:
            self._physics.step(self.actuator_commands, self.physics_step_s)
            self._ekf.step(self.physics_step_s)
            self._steps += 1

    def _compute_outputs(self) -> tuple[float, float]:
        """(nT, nS) percent the firmware commands now (see the module's simplifications)."""
        if not self.armed or self.mode != MANUAL:
            return (0.0, 0.0)
        m = self._mapping
        pwm = {ch: self._rc.pwm(ch, self._params, self.boot_s)
               for ch in (m.steering.channel, m.throttle.channel)}
        return m.to_commands(pwm)

    # -- receiving -------------------------------------------------------------------------
    def _readable(self) -> bool:
        fd = getattr(self._conn, "fd", None)
        if fd is None or fd < 0:
            return False
        try:
            return bool(select.select([fd], [], [], 0)[0])
        except (OSError, ValueError):
            return False

    def _receive_all(self) -> None:
        if self._datagrams:
            self._receive_datagrams()
        else:
            self._receive_stream()

    def _receive_datagrams(self) -> None:
        """UDP: each datagram is parsed whole; a frame cut short at its end is dropped, so
        that it cannot swallow the start of the next datagram's good frames."""
        mav = self._conn.mav
        for _ in range(MAX_MESSAGES_PER_PUMP):
            try:
                data = self._conn.recv()
            except OSError:
                return
            if not data:
                return
            try:
                msgs = mav.parse_buffer(data) or []
            except Exception:  # noqa: BLE001 - pymavlink raises many types on bad input
                msgs = []
                self.counters.bad_data += 1
            if mav.buf_len() > 0:
                mav.buf, mav.buf_index = bytearray(), 0
                mav.expected_length = _mavlink2().HEADER_LEN_V1 + 2
                self.counters.bad_data += 1
            for msg in msgs:
                self._post(msg)

    def _receive_stream(self) -> None:
        for _ in range(MAX_MESSAGES_PER_PUMP):
            try:
                msg = self._conn.recv_msg()
            except Exception:  # noqa: BLE001 - pymavlink raises many types on bad input
                self.counters.bad_data += 1
                continue
            if msg is None:
                if not self._readable():
                    return
                continue
            self._handle(msg)

    def _post(self, msg) -> None:
        """pymavlink's bookkeeping (as recv_msg does), then our handling."""
        if msg.get_type() != "BAD_DATA":
            try:
                self._conn.post_message(msg)
            except Exception:  # noqa: BLE001 - bookkeeping must not stop the handling
                pass
        self._handle(msg)

    def _handle(self, msg) -> None:
        if counted_as_bad_data(msg, self.counters):
            return
        kind = msg.get_type()
        self.counters.messages += 1
        handler = self._HANDLERS.get(kind)
        if handler is None:
            return
        try:
            handler(self, msg)
        except (ValueError, TypeError, OverflowError):
            self.counters.bad_fields += 1

    def _for_us(self, msg) -> bool:
        """Addressed to this vehicle (or broadcast) and to the autopilot component (or all)."""
        ts = getattr(msg, "target_system", 0)
        tc = getattr(msg, "target_component", 0)
        return ts in (0, self._sysid) and tc in (0, COMPONENT_ID)

    def _on_statustext(self, msg) -> None:
        text = msg.text
        if isinstance(text, (bytes, bytearray)):
            text = text.decode("utf-8", "replace")
        self.received_statustext.append(str(text).split("\x00", 1)[0])

    def _on_override(self, msg) -> None:
        ignore = bool(_int(self._params.get("RC_OPTIONS")) & ardupilot.RC_OPTION_IGNORE_OVERRIDES)
        if (msg.target_system != self._sysid or msg.get_srcSystem() != self._params.gcs_sysid
                or ignore):
            self.counters.overrides_ignored += 1
            return
        values = [getattr(msg, f"chan{i}_raw", 0) for i in range(1, 19)]
        self._rc.apply(values, self.boot_s, ignore)
        self._outputs = self._compute_outputs()

    def _on_timesync(self, msg) -> None:
        """Answer a TIMESYNC request (tc1 = 0) with our clock in ns, echoing ts1, as ArduPilot."""
        if msg.tc1 == 0:
            self._conn.mav.timesync_send(int(self.boot_s * 1e9) + 1, msg.ts1)

    def _on_request_data_stream(self, msg) -> None:
        """The legacy REQUEST_DATA_STREAM: a group of streams at one rate (0 or stop: off)."""
        if not self._for_us(msg):
            return
        ids = st.DATA_STREAM_GROUPS.get(msg.req_stream_id, ())
        if msg.req_stream_id == 0:  # MAV_DATA_STREAM_ALL
            ids = [i for group in st.DATA_STREAM_GROUPS.values() for i in group]
        rate = float(msg.req_message_rate)
        interval_us = 1e6 / rate if msg.start_stop and rate > 0 else -1
        for msg_id in ids:
            self._streams.set_interval_us(msg_id, interval_us, self.boot_s)

    def _on_set_mode(self, msg) -> None:
        if msg.target_system != self._sysid:
            return
        result = self._set_mode_common(msg.base_mode, msg.custom_mode)
        self._ack(11, result, msg)  # ArduPilot ACKs the SET_MODE message as "command 11"

    # -- parameters ------------------------------------------------------------------------
    def _send_param(self, name: str) -> None:
        mav = _mavlink2()
        self._conn.mav.param_value_send(
            name.encode("ascii"), float(self._params[name]), mav.MAV_PARAM_TYPE_REAL32,
            len(self._params), self._params.index(name))

    def _on_param_read(self, msg) -> None:
        if not self._for_us(msg):
            return
        if msg.param_index >= 0:
            name = self._params.by_index(msg.param_index)
        else:
            name = param_id(msg.param_id)
        if name is not None and self._params.index(name) is not None:
            self._send_param(name)

    def _on_param_list(self, msg) -> None:
        if self._for_us(msg):
            self._param_queue = deque(range(len(self._params)))

    def _on_param_set(self, msg) -> None:
        if not self._for_us(msg):
            return
        name = param_id(msg.param_id)
        if self._params.set(name, float(msg.param_value)):
            self._param_changed(name)
            self._send_param(name)

    def _param_changed(self, name: str) -> None:
        if self._log is not None:
            self._log.param(self, name, self._params[name])
        if name.startswith("SERVO"):
            try:
                self._servos = CommandChannels.from_servo_params(self._params.values)
            except ValueError as exc:
                self._statustext(f"SERVO: {exc}"[:50], severity=4)
        if name.startswith(("RC", "RCMAP_")) and name not in ("RC_OPTIONS", "RC_OVERRIDE_TIME"):
            try:
                self._mapping = CommandChannels.from_rc_params(self._params.values)
            except ValueError as exc:
                self._statustext(f"RC: {exc}; previous kept"[:50], severity=4)

    # -- commands --------------------------------------------------------------------------
    def _ack(self, command: int, result: int, msg) -> None:
        self._conn.mav.command_ack_send(command, result, 0, 0, msg.get_srcSystem(),
                                        msg.get_srcComponent())

    def _on_command_long(self, msg) -> None:
        if self._for_us(msg):
            p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
            self._ack(msg.command, self._command(msg.command, p), msg)

    def _on_command_int(self, msg) -> None:
        if self._for_us(msg):
            p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z]
            self._ack(msg.command, self._command(msg.command, p), msg)

    def _command(self, command: int, p: list) -> int:
        mav = _mavlink2()
        handlers = {
            mav.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm,
            mav.MAV_CMD_DO_SET_MODE: lambda p: self._set_mode_common(_int(p[0]), _int(p[1], -1)),
            mav.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_set_interval,
            mav.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_interval,
            mav.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_capabilities,
            mav.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: self._cmd_reboot,
        }
        handler = handlers.get(command)
        if handler is None:
            return mav.MAV_RESULT_UNSUPPORTED
        try:
            return handler(p)
        except (ValueError, TypeError, OverflowError):
            self.counters.bad_fields += 1
            return mav.MAV_RESULT_DENIED

    def _cmd_arm(self, p) -> int:
        mav = _mavlink2()
        force = _int(p[1]) == ardupilot.FORCE_ARM_MAGIC
        if p[0] == 1:
            if not self._initialised:
                self._statustext("Arm: System not initialised", severity=2)
                return mav.MAV_RESULT_TEMPORARILY_REJECTED
            if self.armed:
                return mav.MAV_RESULT_ACCEPTED
            if not force and not self._prearm_ok():
                return mav.MAV_RESULT_FAILED
            self.armed = True
            self._statustext("Throttle armed", severity=6)
            if self._log is not None:
                self._log.arm(self, force)
        elif p[0] == 0:
            if self.armed:
                self.armed = False
                self._statustext("Throttle disarmed", severity=6)
                if self._log is not None:
                    self._log.arm(self, force)
        else:
            return mav.MAV_RESULT_UNSUPPORTED
        self._outputs = self._compute_outputs()
        return mav.MAV_RESULT_ACCEPTED

    def _prearm_ok(self) -> bool:
        if self._params.position_check_enabled() and not self.ekf_ready:
            self._statustext("PreArm: Need Position Estimate", severity=2)
            return False
        return True

    def _set_mode_common(self, base_mode: int, custom_mode: int) -> int:
        """DO_SET_MODE and SET_MODE: only custom modes, as ArduPilot."""
        mav = _mavlink2()
        if not base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return mav.MAV_RESULT_DENIED
        if not self._initialised:
            self._statustext("Mode change failed: still initialising", severity=4)
            return mav.MAV_RESULT_TEMPORARILY_REJECTED
        name = ardupilot.MODE_NAMES.get(custom_mode)
        if name is None or name == "INITIALISING":
            self._statustext(f"Unknown mode {custom_mode}", severity=4)
            return mav.MAV_RESULT_FAILED
        if custom_mode in NEEDS_ESTIMATE and not self.ekf_ready:
            self._statustext(f"Mode change to {name} failed: requires position", severity=4)
            return mav.MAV_RESULT_FAILED
        if custom_mode != self.mode:
            self.mode = custom_mode
            self._statustext(f"Mode {name}", severity=6)
            if self._log is not None:
                self._log.mode(self)
            self._outputs = self._compute_outputs()
        return mav.MAV_RESULT_ACCEPTED

    def _cmd_set_interval(self, p) -> int:
        mav = _mavlink2()
        msg_id, interval = _int(p[0], -1), float(p[1])
        if self._streams.set_interval_us(msg_id, interval, self.boot_s):
            return mav.MAV_RESULT_ACCEPTED
        return mav.MAV_RESULT_DENIED

    def _cmd_get_interval(self, p) -> int:
        mav = _mavlink2()
        msg_id = _int(p[0], -1)
        if not self._streams.supports(msg_id):
            return mav.MAV_RESULT_DENIED
        self._conn.mav.message_interval_send(msg_id, self._streams.interval_us(msg_id))
        return mav.MAV_RESULT_ACCEPTED

    def _cmd_request_message(self, p) -> int:
        mav = _mavlink2()
        msg_id = _int(p[0], -1)
        if not (self._streams.supports(msg_id) or msg_id == mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION):
            return mav.MAV_RESULT_DENIED
        self._oneshot.append(msg_id)
        return mav.MAV_RESULT_ACCEPTED

    def _cmd_capabilities(self, p) -> int:
        mav = _mavlink2()
        if _int(p[0]) != 1:
            return mav.MAV_RESULT_ACCEPTED  # "1: request", anything else: nothing to do
        self._oneshot.append(mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        return mav.MAV_RESULT_ACCEPTED

    def _cmd_reboot(self, p) -> int:
        mav = _mavlink2()
        if _int(p[0]) != 1:
            return mav.MAV_RESULT_UNSUPPORTED
        if self.armed:
            self._statustext("Reboot refused: disarm first", severity=4)
            return mav.MAV_RESULT_FAILED
        self._reboot_pending = True
        return mav.MAV_RESULT_ACCEPTED

    # -- sending ---------------------------------------------------------------------------
    def _statustext(self, text: str, severity: int = 6) -> None:
        if self._conn is not None:
            self._conn.mav.statustext_send(severity, text.encode("utf-8")[:50])
        if self._log is not None:
            self._log.text(self, text)

    def _send_due(self) -> None:
        for _ in range(min(PARAMS_PER_PUMP, len(self._param_queue))):
            self._send_param(self._params.by_index(self._param_queue.popleft()))
        for msg_id in self._oneshot:
            self._send(msg_id)
        self._oneshot = []
        for msg_id in self._streams.due(self.boot_s):
            self._send(msg_id)

    def _send(self, msg_id: int) -> None:
        sender = self._SENDERS.get(msg_id)
        if sender is not None:
            sender(self)

    @property
    def _time_boot_ms(self) -> int:
        return max(0, int(round(self.boot_s * 1000.0)))

    def _send_heartbeat(self) -> None:
        mav = _mavlink2()
        base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.mode in MANUAL_INPUT_MODES:
            base |= mav.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        elif self.mode not in (HOLD, INITIALISING):
            base |= mav.MAV_MODE_FLAG_GUIDED_ENABLED
        if self.armed:
            base |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        if not self._initialised:
            status = mav.MAV_STATE_CALIBRATING
        elif self.mode == HOLD:
            status = mav.MAV_STATE_STANDBY
        else:
            status = mav.MAV_STATE_ACTIVE
        self._conn.mav.heartbeat_send(mav.MAV_TYPE_SURFACE_BOAT, mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                      base, self.mode, status)

    def _send_sys_status(self) -> None:
        mav = _mavlink2()
        present = (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                   | mav.MAV_SYS_STATUS_SENSOR_3D_MAG | mav.MAV_SYS_STATUS_SENSOR_GPS
                   | mav.MAV_SYS_STATUS_AHRS)
        health = present if self.ekf_ready else present & ~(mav.MAV_SYS_STATUS_SENSOR_GPS
                                                            | mav.MAV_SYS_STATUS_AHRS)
        self._conn.mav.sys_status_send(present, present, health, 100, 12600, -1, -1,
                                       0, 0, 0, 0, 0, 0)

    def _estimate(self):
        return self._ekf.estimate(self.last_plant_output.state)

    def _send_attitude(self) -> None:
        e = self._estimate()
        self._conn.mav.attitude_send(self._time_boot_ms, 0.0, 0.0, e.psi_rad, 0.0, 0.0, e.r_radps)

    def _send_local_position(self) -> None:
        if not self.ekf_ready or self.ekf_origin is None:
            return  # ArduPilot sends it only with a valid position
        e = self._estimate()
        lat, lon = ned_to_geodetic(e.north_m, e.east_m, self._origin)
        north, east = geodetic_to_ned(lat, lon, self.ekf_origin)  # from the EKF origin
        self._conn.mav.local_position_ned_send(self._time_boot_ms, north, east, 0.0,
                                               e.vn_mps, e.ve_mps, 0.0)

    def _send_gps_global_origin(self) -> None:
        if self.ekf_origin is None:
            return  # as ArduPilot: nothing to say before the origin is set
        lat, lon, alt = self.ekf_origin
        self._conn.mav.gps_global_origin_send(int(round(lat * 1e7)), int(round(lon * 1e7)),
                                              int(round(alt * 1000.0)),
                                              int(self.boot_s * 1e6))

    def _send_global_position(self) -> None:
        if not self.ekf_ready:
            return
        e = self._estimate()
        lat, lon = ned_to_geodetic(e.north_m, e.east_m, self._origin)
        alt_mm = int(round(self._origin[2] * 1000.0))
        hdg = int(round(math.degrees(e.psi_rad) % 360.0 * 100.0)) % 36000
        cm = lambda v: max(-32768, min(32767, int(round(v * 100.0))))  # noqa: E731
        self._conn.mav.global_position_int_send(
            self._time_boot_ms, int(round(lat * 1e7)), int(round(lon * 1e7)), alt_mm, 0,
            cm(e.vn_mps), cm(e.ve_mps), 0, hdg)

    def _send_ekf_status(self) -> None:
        mav = _mavlink2()
        flags = mav.EKF_ATTITUDE
        if self.ekf_ready:
            flags |= (mav.EKF_VELOCITY_HORIZ | mav.EKF_POS_HORIZ_REL | mav.EKF_POS_HORIZ_ABS
                      | mav.EKF_PRED_POS_HORIZ_REL | mav.EKF_PRED_POS_HORIZ_ABS)
        self._conn.mav.ekf_status_report_send(flags, 0.02, 0.03, 0.0, 0.02, 0.0)

    def _send_rc_channels(self) -> None:
        chans = self._rc.channels(self._params, self.boot_s, 16) + [UINT16_MAX, UINT16_MAX]
        self._conn.mav.rc_channels_send(self._time_boot_ms, 16, *chans, 255)

    def _send_servo_output(self) -> None:
        """Servo outputs 1-16 (SERVOn_FUNCTION/MIN/MAX/TRIM/REVERSED: by default output 1
        steers, above trim to starboard, and output 3 throttles; 1100-1900 us)."""
        self._conn.mav.servo_output_raw_send((self._time_boot_ms * 1000) & 0xFFFFFFFF, 0,
                                             *self.servo_outputs(16))

    def _send_autopilot_version(self) -> None:
        mav = _mavlink2()
        major, minor, patch = FIRMWARE[self._params.legacy]
        caps = (mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT)
        version = (major << 24) | (minor << 16) | (patch << 8) | mav.FIRMWARE_VERSION_TYPE_OFFICIAL
        self._conn.mav.autopilot_version_send(caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                              0, 0, self._sysid)

    _HANDLERS = {
        "STATUSTEXT": _on_statustext,
        "RC_CHANNELS_OVERRIDE": _on_override,
        "SET_MODE": _on_set_mode,
        "TIMESYNC": _on_timesync,
        "REQUEST_DATA_STREAM": _on_request_data_stream,
        "PARAM_REQUEST_READ": _on_param_read,
        "PARAM_REQUEST_LIST": _on_param_list,
        "PARAM_SET": _on_param_set,
        "COMMAND_LONG": _on_command_long,
        "COMMAND_INT": _on_command_int,
    }
    _SENDERS = {
        st.HEARTBEAT: _send_heartbeat,
        st.SYS_STATUS: _send_sys_status,
        st.ATTITUDE: _send_attitude,
        st.LOCAL_POSITION_NED: _send_local_position,
        st.GLOBAL_POSITION_INT: _send_global_position,
        st.EKF_STATUS_REPORT: _send_ekf_status,
        st.RC_CHANNELS: _send_rc_channels,
        st.SERVO_OUTPUT_RAW: _send_servo_output,
        st.GPS_GLOBAL_ORIGIN: _send_gps_global_origin,
        148: _send_autopilot_version,  # AUTOPILOT_VERSION, on request only
    }
