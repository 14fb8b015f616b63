"""The onboard loop: the NMPC driving an ArduPilot Rover boat over MAVLink at 10 Hz.

`prepare_link` takes a connected `AutopilotLink` from "heard nothing" to "ready to steer":
heartbeat, message rates, RC parameters, pre-flight refusals, a usable EKF position, and the
mode and arming only when asked. `OnboardLoop.run` then closes the loop on the link's clock:
the EKF state predicted over the link delay, segments from the LiDAR source, the controller,
RC overrides out. On a lost link, a stale state, a controller failure, an error or Ctrl-C it
fails safe: neutral commands, overrides released, HOLD if it controls the mode, and the
reason on the console and to the ground station. `run_bridge` wires it all from options.

Exit codes: 0 goal reached; 1 stopped (time limit, failsafe); 3 pre-flight refused; 130 Ctrl-C.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from controller.errors import CanalnavError, InputError

from bridge.onboard.lateness import Lateness
from bridge.onboard.step_log import Step, StepLog, status_line

EXIT_GOAL, EXIT_STOPPED, EXIT_REFUSED, EXIT_INTERRUPTED = 0, 1, 3, 130
MAV_SEVERITY_CRITICAL, MAV_SEVERITY_WARNING, MAV_SEVERITY_INFO = 2, 4, 6


class PreflightRefused(CanalnavError):
    """The autopilot would not obey (or must not be driven); `reasons` says why, each naming
    the parameter and its value."""

    def __init__(self, reasons: list[str]):
        self.reasons = list(reasons)
        super().__init__("pre-flight checks refused: " + "; ".join(self.reasons))


@dataclass(frozen=True)
class BridgeOptions:
    """Everything `canalnav bridge` takes (SI units, seconds)."""

    connect: str = ""
    scenario: str | Path | None = None
    lidar: str | tuple = "sim"  # one source, or several (merged; see bridge.lidar)
    lidar_config: str | Path | None = None  # --lidar-config FILE (else the scenario's [lidar])
    arm: bool = False
    mode: str | None = None
    signing_key: str | Path | None = None
    duration_s: float | None = None
    resume: bool = False
    log_dir: str | Path | None = None
    system_id: int = 255
    component_id: int = 191
    target_system: int | None = None
    link_timeout_s: float = 3.0
    stale_s: float = 1.0
    speedup: float = 1.0
    ekf_timeout_s: float = 120.0
    heartbeat_timeout_s: float = 30.0
    startup_timeout_s: float = 60.0  # for the autopilot to finish its start-up
    origin: tuple | None = None  # (lat_deg, lon_deg, alt_m) of the scenario's (0, 0); else its [origin]
    origin_timeout_s: float = 5.0  # for GPS_GLOBAL_ORIGIN
    stream_rate_hz: float = 20.0
    control_period_s: float = 0.1
    seed: int | None = None  # simulated LiDAR noise (default: the scenario's seed)
    mcap: bool | None = None  # run.mcap in log_dir (None: when the viz extra is installed)
    live: tuple | None = None  # (host, port): serve the steps live to Foxglove
    cloud_points: int = 3000  # LiDAR points per scan kept for run.mcap and the live view
    safe_repeats: int = 3  # neutral and release are each sent this often, 50 ms apart
    # A jump of the EKF's position (a GPS glitch it took in, a reset) is taken out of the
    # state the controller gets, held out `jump_hold_s` after the last jump (a glitch that
    # jumps back meanwhile cancels itself) and then let back in with the time constant
    # `jump_blend_s` (0: at once), so that the boat does not steer after a jump it did not
    # make, and follows one that stays (a reset to a better fix) smoothly.
    jump_hold_s: float = 10.0
    jump_blend_s: float = 30.0


@dataclass
class Preparation:
    """What `prepare_link` found: the autopilot's heartbeat, the parameters read, notes."""

    heartbeat: object
    params: dict
    streams: dict
    notes: list = field(default_factory=list)


@dataclass
class BridgeResult:
    exit_code: int
    reason: str
    steps: int = 0
    reached_goal: bool = False
    failsafes: list = field(default_factory=list)
    late_steps: int = 0  # control steps more than 1.5 periods after the last
    gaps: int = 0  # of them a second or more after the last
    worst_late_s: float = 0.0


def _say(console, text: str) -> None:
    if console is not None:
        console.write(text + "\n")
        console.flush()


NO_ORIGIN = (
    "no geodetic origin: the scenario {source} has no [origin] and --origin was not given. "
    "ArduPilot measures LOCAL_POSITION_NED from its EKF origin, which is wherever the boat was "
    "at its first GPS fix, not the scenario's (0, 0); the bridge places the scenario on the "
    "Earth instead. Give the latitude and longitude of the scenario's (0, 0): "
    "[origin] lat_deg = ..., lon_deg = ... in the scenario file, or --origin=LAT,LON[,ALT] "
    "(against ArduPilot SITL or canalnav autopilot-sim with a scenario without [origin], "
    "their default home: --origin={home}; with '=' since it starts with a minus)")


def geodetic_origin(scenario, options: BridgeOptions):
    """The scenario's place on the Earth: --origin, else its [origin]; InputError if none."""
    from bridge.shared.ardupilot import SITL_DEFAULT_HOME

    origin = options.origin or scenario.geodetic_origin
    if origin is None:
        home = format_origin(SITL_DEFAULT_HOME)
        raise InputError(NO_ORIGIN.format(source=scenario.path or scenario.name, home=home))
    return tuple(float(v) for v in origin)


def format_origin(origin) -> str:
    """(lat, lon, alt) as `LAT,LON,ALT` for --origin (to 1e-7 degrees, about a centimetre)."""
    return ",".join(f"{float(v):.7f}".rstrip("0").rstrip(".") for v in origin)


def parse_origin(text: str) -> tuple[float, float, float]:
    """`LAT,LON[,ALT]` (degrees, metres) -> (lat, lon, alt); InputError names the problem."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) not in (2, 3):
        raise InputError(f"--origin {text!r}: expected LAT,LON or LAT,LON,ALT (degrees, metres)")
    try:
        values = [float(p) for p in parts] + ([0.0] if len(parts) == 2 else [])
    except ValueError:
        raise InputError(f"--origin {text!r}: not numbers (expected LAT,LON[,ALT])") from None
    lat, lon, alt = values
    if not all(math.isfinite(v) for v in values) or not -90 <= lat <= 90 or not -180 <= lon <= 180:
        raise InputError(f"--origin {text!r}: latitude must lie in -90..90 and longitude in "
                         "-180..180 degrees")
    return lat, lon, alt


def _check_ekf_origin(link, options, console) -> None:
    """GPS_GLOBAL_ORIGIN: where the EKF origin is, and whether LOCAL_POSITION_NED moved by it
    agrees with GLOBAL_POSITION_INT (refused if not)."""
    from bridge.onboard.link import FRAME_TOLERANCE_M

    origin = link.wait_ekf_origin(options.origin_timeout_s)
    if origin is None:
        _say(console, f"note: no GPS_GLOBAL_ORIGIN within {options.origin_timeout_s:g} s: "
                      "positions from GLOBAL_POSITION_INT only, LOCAL_POSITION_NED not "
                      "cross-checked")
        return
    n, e = link.ekf_origin_ne
    _say(console, f"EKF origin: {origin[0]:.7f}, {origin[1]:.7f} ({n:.1f} m north, {e:.1f} m "
                  "east of the scenario's (0, 0): where the boat was at its first GPS fix)")
    link.frame_mismatch_m = None
    link.wait_until(lambda: link.frame_mismatch_m is not None, 1.0)
    if link.frame_mismatch_m is not None and link.frame_mismatch_m > FRAME_TOLERANCE_M:
        raise PreflightRefused([link.frame_disagreement() + "; the autopilot's frames disagree"])
    link.pop_notices()


def _rc_summary(m) -> str:
    def one(c):
        rev = ", reversed" if c.reversed else ""
        return f"channel {c.channel} ({c.min}/{c.trim}/{c.max} us, dead zone {c.dz} us{rev})"
    return f"RC: throttle {one(m.throttle)}, steering {one(m.steering)}"


def _read_rc_params(link) -> dict:
    """The parameters the pre-flight checks and the RC mapping need, read until settled."""
    from bridge.onboard import preflight

    params = link.wait_params_settled(preflight.BASE_PARAMS + preflight.GCS_SYSID_NAMES,
                                      optional=(preflight.GCS_SYSID_HIGH,))
    params.update(link.wait_params_settled(preflight.channel_params(params)))
    return params


def prepare_link(link, scenario, options: BridgeOptions = BridgeOptions(), console=None) -> Preparation:
    """Bounded, named waits from "heard nothing" to "ready to steer", as ArduPilot's autotest
    does them: heartbeat, past start-up, stream rates, RC parameters (read until settled),
    pre-flight checks, EKF position, the RC parameters again just before taking control, then
    the mode and arming if asked. Raises PreflightRefused (with reasons) or LinkError."""
    from bridge.onboard import preflight
    from controller.pwm import CommandChannels

    link.geodetic_origin = geodetic_origin(scenario, options)
    hb = link.wait_heartbeat(options.heartbeat_timeout_s)
    _say(console, f"autopilot: system {hb.system_id} component {hb.component_id}, "
                  f"{'boat' if hb.type == preflight.MAV_TYPE_SURFACE_BOAT else 'rover'}, "
                  f"{hb.mode}, {'armed' if hb.armed else 'disarmed'}")
    if hb.custom_mode == 16 or hb.system_status in (0, 1, 2):
        _say(console, "autopilot: starting up; waiting for it to finish before reading "
                      "parameters")
    hb = link.wait_past_startup(options.startup_timeout_s)
    streams = link.request_streams(options.stream_rate_hz)
    unanswered = [k for k, v in streams.items() if v != 0]
    if unanswered:
        _say(console, "note: SET_MESSAGE_INTERVAL not accepted for " + ", ".join(
            f"{k} ({'no answer' if streams[k] is None else f'result {streams[k]}'})" for k in unanswered))
    params = _read_rc_params(link)
    reasons = preflight.refusals(link.heartbeat, params, system_id=link.system_id,
                                 requested_mode=options.mode)
    if reasons:
        raise PreflightRefused(reasons)
    link.rc_mapping = CommandChannels.from_rc_params(params)
    notes = preflight.notes(link.heartbeat, params, arm=options.arm, requested_mode=options.mode)
    for note in notes:
        _say(console, f"note: {note}")
    _say(console, _rc_summary(link.rc_mapping))
    link.wait_position_ok(options.ekf_timeout_s)
    _say(console, "EKF: horizontal position usable")
    _check_ekf_origin(link, options, console)
    # again, just before taking control: a parameter may have changed while we waited
    again = _read_rc_params(link)
    changed = sorted(n for n in set(params) | set(again) if params.get(n) != again.get(n))
    if changed:
        for n in changed:
            _say(console, f"note: {n} changed from {params.get(n)} to {again.get(n)} since it was "
                          "first read; using the new value")
        reasons = preflight.refusals(link.heartbeat, again, system_id=link.system_id,
                                     requested_mode=options.mode)
        if reasons:
            raise PreflightRefused(reasons)
        link.rc_mapping = CommandChannels.from_rc_params(again)
        _say(console, _rc_summary(link.rc_mapping))
    params = again
    link.pop_param_changes()  # accounted for; the loop logs those that come from now on
    if options.mode:  # always: the heartbeat (1 Hz) may not show our own HOLD yet
        link.set_mode(options.mode)
        _say(console, f"mode set to {options.mode.upper()}")
    if options.arm and not link.heartbeat.armed:
        link.arm()
        _say(console, "armed")
    return Preparation(link.heartbeat, params, streams, notes)


def link_fault(link) -> str | None:
    """Why nothing may be steered now (short: it goes to the ground station), or None: the
    link lost, the state stale, the EKF's position unusable."""
    if not link.alive:
        return f"link lost ({link.silence_s:.1f} s silent)"
    if not link.state_fresh:
        return f"state stale ({link.state_age_s:.1f} s old)"
    if not link.horizontal_position_ok:
        flags = link.ekf_flags
        return f"EKF position unusable (flags {'none' if flags is None else hex(flags)})"
    return None


def safe_stop(link, options: BridgeOptions, reason: str, severity: int) -> str:
    """Neutral (`safe_repeats` times, 50 ms apart), overrides released, HOLD if the mode is
    ours, then the reason to the ground station; what happened to the mode (for the console)."""
    if link.rc_mapping is not None:
        for _ in range(options.safe_repeats):
            link.send_neutral()
            link.idle(0.05)
        for _ in range(options.safe_repeats):
            link.release()
            link.idle(0.05)
    held = ""
    if options.mode:
        try:
            link.set_mode("HOLD", timeout_s=0.5, retries=2)
            held = ", HOLD"
        except CanalnavError as exc:
            held = f", HOLD failed ({exc})"
    link.statustext(f"canalnav: {reason}", severity)
    return held


def nearest_segment_m(position, segments) -> float:
    """Distance from a point to the nearest segment (x_c, y_c, theta, length); inf if none."""
    from controller.geometry import point_segment_distance, segments_to_endpoints

    segs = np.asarray(segments, float).reshape(-1, 4)
    if not len(segs):
        return math.inf
    a, b = segments_to_endpoints(segs)
    return float(point_segment_distance(np.asarray(position, float)[:2], a, b).min())


class OnboardLoop:
    """The control loop on an injected link, controller and LiDAR source (see module doc).

    Everything waits on `link.clock`, so with a VirtualClock and a simulated autopilot as its
    peer the whole run is deterministic in one thread.
    """

    def __init__(self, link, scenario, controller, lidar, options: BridgeOptions = BridgeOptions(),
                 console=sys.stderr, log: StepLog | None = None):
        self.link = link
        self.clock = link.clock
        self.scenario = scenario
        self.controller = controller
        self.lidar = lidar
        self.options = options
        self.console = console
        self.log = log or StepLog(None)
        self.steps = 0
        self.failsafes: list[str] = []
        self._t0 = 0.0
        self._actuators = np.zeros(2)
        self._tty = bool(getattr(console, "isatty", lambda: False)())
        self._status_shown = False
        self.perception = _perception_for(lidar)  # detection, vessel tracking, cleaning, gaps
        import inspect

        takes = inspect.signature(controller.step).parameters  # an older controller takes
        self._takes = {"blind", "vessels"} & set(takes)  # neither blindness nor vessels
        self._waiting = ""  # why the NMPC holds the boat ("way blocked", "blind"), if it does
        self.lateness = Lateness(options.control_period_s)  # steps late, gaps
        self._jumps_seen = np.zeros(2)  # the link's sum of jumps at the last step
        self._jump_offset = np.zeros(2)  # (north, east) m taken out of the state (jump_blend_s)
        self._jump_t = None

    # -- the run ---------------------------------------------------------------------------
    def run(self) -> BridgeResult:
        try:
            prepare_link(self.link, self.scenario, self.options, self.console)
        except PreflightRefused as exc:
            self._say("bridge: refused to start:\n  - " + "\n  - ".join(exc.reasons))
            return BridgeResult(EXIT_REFUSED, str(exc))
        self._t0 = self.clock.now()
        try:
            return self._loop()
        except KeyboardInterrupt:
            self._fail_safe("interrupted (Ctrl-C)")
            return self._result(EXIT_INTERRUPTED, "interrupted (Ctrl-C)")
        except Exception as exc:
            try:
                self._fail_safe(f"bridge error: {exc}")
            except Exception:  # noqa: BLE001 - the original error matters more
                pass
            raise

    def _loop(self) -> BridgeResult:
        period = self.options.control_period_s
        goal = np.asarray(self.scenario.waypoints, float)[-1]
        next_t = self.clock.now()
        while True:
            self.link.pump()
            t = self.clock.now() - self._t0
            if self.options.duration_s is not None and t >= self.options.duration_s:
                self._stop("time limit", MAV_SEVERITY_WARNING)
                return self._result(EXIT_STOPPED, "time limit")
            fault = self._follow_params(t) or self._fault()
            if fault is None:
                state = self.link.state
                if np.hypot(state.x - goal[0], state.y - goal[1]) <= self.scenario.goal_radius_m:
                    self._stop("reached the goal", MAV_SEVERITY_INFO)
                    return self._result(EXIT_GOAL, "reached the goal", reached=True)
                fault = self._step(t)
            if fault is not None:
                self._fail_safe(fault)
                if not self.options.resume:
                    return self._result(EXIT_STOPPED, fault)
                stopped = self._recover()
                if stopped is not None:
                    return stopped
                self.lateness.pause()  # (the wait to resume is no lateness)
                next_t = self.clock.now()
                continue
            next_t += period
            wait = next_t - self.clock.now()
            if wait > 1e-9:
                self.link.idle(wait)  # messages are read (and stamped) as they arrive
            else:
                next_t = self.clock.now()

    def _follow_params(self, t: float) -> str | None:
        """Log each parameter the autopilot reported changed (the link has applied it: the RC
        mapping follows); a change that makes the autopilot ignore us is a fault."""
        from bridge.onboard import preflight

        hb = self.link.heartbeat
        for _, notice in self.link.pop_notices():
            self.log.event(t, notice, hb.mode if hb else "", hb.armed if hb else None)
            self._say(f"bridge: {notice}")
        changes = self.link.pop_param_changes()
        if not changes:
            return None
        for change in changes:
            self.log.event(t, change.describe(), hb.mode if hb else "", hb.armed if hb else None)
            self._say(f"bridge: {change.describe()}")
        names = {c.name for c in changes}
        reasons = [r for r in preflight.refusals(hb, self.link.params, system_id=self.link.system_id,
                                                 requested_mode=self.options.mode or "MANUAL")
                   if any(n in r for n in names)]
        return f"parameter change: {reasons[0]}" if reasons else None

    def _fault(self) -> str | None:
        """Why the loop must not steer now (short: it goes to the ground station), or None."""
        return link_fault(self.link)

    def _step(self, t: float) -> str | None:
        """One control period; returns a fault that calls for the failsafe, else None."""
        from bridge.onboard.ekf_state import predict_vector

        _, warning = self.lateness.tick(t)
        if warning:  # said to the log, the console and the ground station
            hb = self.link.heartbeat
            self.log.event(t, warning, hb.mode if hb else "", hb.armed if hb else None)
            self.link.statustext(f"canalnav: {warning}"[:200], MAV_SEVERITY_WARNING)
            self._say(f"bridge: warning: {warning}")
        link = self.link
        state = link.state
        age, delay = link.state_age_s, link.link_delay_s
        pred = predict_vector(state.vector, age + delay)
        pred[:2] -= self._blend_jumps(t)
        cloud = self.lidar.scan(t, pred)
        lost = self._lidar_health(t)
        if lost is not None:
            return lost
        view = self.perception.update(t, cloud, pred)
        segs = view.segments
        t0 = time.perf_counter()
        extra = {k: v for k, v in (("blind", view.blind), ("vessels", view.tracks))
                 if k in self._takes}
        decision = self.controller.step(t, pred, self._actuators.copy(), segs, **extra)
        solve_ms = (time.perf_counter() - t0) * 1e3
        hb = link.heartbeat
        if not decision.ok:
            return f"controller failed: {decision.status}"
        command = np.clip(np.asarray(decision.command, float).reshape(2), -100.0, 100.0)
        if not np.all(np.isfinite(command)):
            return f"controller failed: command {command.tolist()} is not a number"
        pwm = link.send_commands(*command)
        prepare = getattr(self.controller, "prepare", None)
        if prepare is not None:  # the command is out: prepare the next step now
            prepare()
        self._actuators = command
        self._tell_waiting(t, str(decision.stats.get("waiting", "")))
        m = link.rc_mapping
        step = Step(t, state.time_boot_s, age, delay, state.vector, pred, command,
                    (pwm.get(m.throttle.channel), pwm.get(m.steering.channel)), segs,
                    nearest_segment_m(pred, segs), solve_ms, float(decision.slack_m),
                    hb.mode, hb.armed, str(decision.status), view=view,
                    water=decision.stats.get("water"), cloud=cloud, plan=decision.predicted,
                    current_used=decision.stats.get("current_used"))
        self.log.step(step)
        self.steps += 1
        self._show(step)
        return None

    def _blend_jumps(self, t: float) -> np.ndarray:
        """The part of the EKF's position jumps still taken out of the state (north, east):
        each new jump the link saw is added at once and restarts the hold; after
        `jump_hold_s` the whole decays with `jump_blend_s`."""
        hold, tau = self.options.jump_hold_s, self.options.jump_blend_s
        jumps = np.asarray(self.link.jumps_ne, float)
        new = jumps - self._jumps_seen
        self._jumps_seen = jumps
        if tau <= 0:
            return self._jump_offset
        if self._jump_t is not None and t > self._jump_t and np.any(self._jump_offset):
            self._jump_offset *= math.exp(-(t - self._jump_t) / tau)
            self._jump_t = t
            if np.hypot(*self._jump_offset) < 0.01:
                self._jump_offset[:] = 0.0
        if np.any(new):
            self._jump_offset += new
            self._jump_t = t + hold  # decay starts here
        return self._jump_offset

    def _lidar_health(self, t: float) -> str | None:
        """What a merged LiDAR source has to say (a sensor silent or back, malformed packets
        skipped) to the log, console and ground station; its failsafe reason, if any."""
        hb = self.link.heartbeat
        for text, severity in getattr(self.lidar, "pop_notices", list)():
            self.log.event(t, text, hb.mode if hb else "", hb.armed if hb else None)
            self.link.statustext(f"canalnav: {text}"[:200], severity)
            self._say(f"bridge: {text}")
        lost = getattr(self.lidar, "lost", None)
        return lost(t) if lost is not None else None

    def _lidar_lost(self) -> str | None:
        """While waiting to resume: read the LiDAR (at the newest state, if any) and say
        what it says; the failsafe's reason while every sensor is still silent."""
        if getattr(self.lidar, "lost", None) is None:
            return None
        t = self.clock.now() - self._t0
        state = self.link.state
        pose = state.vector if state is not None else np.zeros(6)
        self.lidar.scan(t, pose)
        return self._lidar_health(t)

    def _tell_waiting(self, t: float, waiting: str) -> None:
        """When the NMPC starts or stops holding the boat short of a blocked way (or blind),
        say so once: the log, the console and the ground station (STATUSTEXT)."""
        from controller.nmpc.passage import waiting_kind

        why = waiting_kind(waiting)
        if why == self._waiting:
            return
        self._waiting = why
        text = f"waiting: {waiting}" if waiting else "the way is clear: going on"
        hb = self.link.heartbeat
        self.log.event(t, text, hb.mode if hb else "", hb.armed if hb else None)
        self.link.statustext(f"canalnav: {text}",
                             MAV_SEVERITY_WARNING if waiting else MAV_SEVERITY_INFO)
        self._say(f"bridge: {text}")

    # -- stopping ------------------------------------------------------------------------------
    def _stop(self, reason: str, severity: int) -> None:
        """Neutral, release, HOLD (if the mode is ours), then tell the ground station."""
        link = self.link
        held = safe_stop(link, self.options, reason, severity)
        self._actuators = np.zeros(2)
        t = self.clock.now() - self._t0
        hb = link.heartbeat
        self.log.event(t, reason, hb.mode if hb else "", hb.armed if hb else None)
        self._say(f"bridge: {reason}: neutral sent, overrides released{held}")

    def _fail_safe(self, reason: str) -> None:
        self.failsafes.append(reason)
        self._stop(f"FAILSAFE {reason}", MAV_SEVERITY_CRITICAL)

    def _recover(self) -> BridgeResult | None:
        """--resume: wait for the link and state to come back, prepare again, continue.
        Returns a result if the run must end instead (time limit, refusal)."""
        from bridge.onboard.link import LinkError

        blind = self._lidar_lost() is not None
        self._say("bridge: waiting for the link and the EKF state" + (" and a LiDAR sweep"
                  if blind else "") + " to come back (--resume)")
        while True:
            remaining = math.inf
            if self.options.duration_s is not None:
                remaining = self.options.duration_s - (self.clock.now() - self._t0)
                if remaining <= 0:
                    return self._result(EXIT_STOPPED, "time limit (waiting to resume)")
            if not self.link.wait_until(lambda: self.link.alive, min(1.0, remaining)):
                continue
            if self._lidar_lost() is not None:  # perception lost: a sweep must come first
                self.link.idle(min(self.options.control_period_s, remaining))
                continue
            try:
                options = self.options
                if remaining < options.ekf_timeout_s:
                    from dataclasses import replace

                    options = replace(options, ekf_timeout_s=max(remaining, 0.1))
                prepare_link(self.link, self.scenario, options, self.console)
            except PreflightRefused as exc:
                self._say("bridge: cannot resume:\n  - " + "\n  - ".join(exc.reasons))
                return self._result(EXIT_REFUSED, str(exc))
            except LinkError as exc:
                self._say(f"bridge: not yet: {exc}")
                continue
            reset = getattr(self.controller, "reset", None) or getattr(
                getattr(self.controller, "core", None), "reset", None)
            if reset is not None:
                reset()
            self._actuators = np.zeros(2)
            self.link.statustext("canalnav: resumed control", MAV_SEVERITY_WARNING)
            self.log.event(self.clock.now() - self._t0, "resumed")
            self._say("bridge: resumed")
            return None

    def _result(self, code: int, reason: str, reached: bool = False) -> BridgeResult:
        late = self.lateness
        if late.summary():
            self._say(f"bridge: {late.summary()}")
        return BridgeResult(code, reason, self.steps, reached, list(self.failsafes),
                            late.late_steps, late.gaps, late.worst_late_s)

    # -- console -------------------------------------------------------------------------------
    def _show(self, step: Step) -> None:
        if self.console is None:
            return
        if self._tty:
            self.console.write("\r" + status_line(step) + "\x1b[K")
            self.console.flush()
            self._status_shown = True
        elif self.steps % 50 == 1:
            self._say(status_line(step))

    def _say(self, text: str) -> None:
        if self._status_shown:
            text = "\n" + text
            self._status_shown = False
        _say(self.console, text)


def _bridge_viz(options: BridgeOptions, log_dir, origin, scenario, console):
    """run.mcap in the log folder (by default when the viz extra is installed) and/or the
    live Foxglove view, or None."""
    from scenarios.results.foxglove_messages import require_viz, viz_available

    mcap = log_dir is not None and (viz_available() if options.mcap is None else options.mcap)
    if not mcap and options.live is None:
        return None
    require_viz()
    from bridge.onboard.step_log import BridgeViz
    from scenarios.loop.runner import R_B_M
    from scenarios.results.mcap_log import VizOptions
    from scenarios.sensors.lidar import LidarConfig

    viz = BridgeViz(VizOptions(mcap_path=log_dir / "run.mcap" if mcap else None,
                               live=options.live, cloud_points=options.cloud_points),
                    origin, LidarConfig().mounts if options.lidar == "sim" else (),
                    hull_radius_m=R_B_M, separation_m=R_B_M + scenario.d_p_m)
    if viz.live_url:
        _say(console, f"bridge: live view for Foxglove on {viz.live_url}")
    return viz


def run_bridge(options: BridgeOptions, console=sys.stderr) -> BridgeResult:
    """`canalnav bridge`: load the scenario, build the controller and LiDAR source, connect,
    prepare, run; the link and logs are closed whatever happens."""
    from bridge.shared.ardupilot import MODES
    from bridge.shared.clock import RealClock
    from bridge.lidar import build_lidar
    from bridge.onboard.link import AutopilotLink
    from scenarios.loop.controllers import NmpcController
    from scenarios.scenario_file import load_scenario

    if options.scenario is None or not options.connect:
        raise InputError("bridge: --connect URL and --scenario FILE are required")
    if options.mode is not None and options.mode.upper() not in MODES:
        raise InputError(f"--mode {options.mode}: not a Rover mode (one of {', '.join(MODES)})")
    for name, value in (("--duration", options.duration_s), ("--speedup", options.speedup),
                        ("--ekf-timeout", options.ekf_timeout_s)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive number, got {value!r}")
    scenario = load_scenario(options.scenario)
    origin = geodetic_origin(scenario, options)  # before connecting: refuse at once
    if options.origin and scenario.geodetic_origin and tuple(options.origin) != tuple(
            scenario.geodetic_origin):
        _say(console, f"bridge: --origin={format_origin(options.origin)} replaces the "
                      "scenario's [origin]")
    key = None
    if options.signing_key is not None:
        from bridge.shared.signing import load_signing_key

        key = load_signing_key(options.signing_key)
    lidar = build_lidar(options.lidar, options.lidar_config, scenario, options.seed)
    log_dir = None if options.log_dir is None else Path(options.log_dir)
    if log_dir is not None:
        log_dir.mkdir(parents=True, exist_ok=True)
    link = AutopilotLink(  # opened before the controller is built: a bad URL fails at once
        options.connect, RealClock(options.speedup), system_id=options.system_id,
        component_id=options.component_id, target_system=options.target_system,
        signing_key=key, tlog_path=None if log_dir is None else log_dir / "mavlink.tlog",
        link_timeout_s=options.link_timeout_s, stale_s=options.stale_s,
        geodetic_origin=origin)
    log = viz = None
    try:
        viz = _bridge_viz(options, log_dir, origin, scenario, console)
        controller = NmpcController(scenario)
        _say(console, f"bridge: sending as system id {options.system_id}, component "
                      f"{options.component_id}: ArduPilot obeys RC overrides only from its GCS "
                      "id (SYSID_MYGCS / MAV_GCS_SYSID)" + (", signed" if key else ""))
        log = StepLog(log_dir, viz)
        return OnboardLoop(link, scenario, controller, lidar, options, console, log).run()
    finally:
        if log is not None:
            log.close()
        elif viz is not None:
            viz.close()
        link.close()
        getattr(lidar, "close", lambda: None)()


def _perception_for(lidar):
    """The scan pipeline for a LiDAR source: free space judged from where its sensors sit
    (`viewpoints`, when the source knows them), the own hull's returns kept as occluders."""
    from controller.perception.pipeline import PipelineConfig, ScanPipeline
    from controller.perception.tracking import TrackerConfig

    viewpoints = tuple(getattr(lidar, "viewpoints", ()) or ())
    return ScanPipeline(PipelineConfig(tracking=TrackerConfig(viewpoints=viewpoints)))
