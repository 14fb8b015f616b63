"""`canalnav maneuvers --connect`: the identification runs driven on the boat over MAVLink.

The runs of `controller.identification.maneuvers` (an acceleration staircase from rest, a
deceleration staircase from steady 50.6 %, the 20 deg / 50 % zigzag at 42 %, the held-out
10 deg / 30 % zigzag) sent as RC overrides in MANUAL, through the same link, start-up and
pre-flight checks as `canalnav bridge`. Each throttle level is held `hold_s` (the EKF's
speed noise makes a steady-state test unreliable on the boat; 60 s is about four surge time
constants of the paper's boat at its slowest level). Commands move no faster than the
actuators (the scenario's rates, over the clock time measured between control steps), so the
servo outputs that the autopilot logs are where the actuators are; control steps that come
late within a run (the loop behind the clock) are counted and reported (between runs a late
step harms nothing). The runs are planned inside the water (`open_water`): how far each goes
is worked out from the model first; before each run the boat goes to open water if it is at
its edge (a start at the end of a canal), turns at low throttle to the heading with the most
water ahead (and stops, for a run from rest), and holds each level shorter if even that water
is too short for the run.

Safe as the bridge: a lost link, a stale state, an unusable EKF position, a parameter change
that makes the autopilot ignore it, or Ctrl-C ends the session with neutral commands, the
overrides released, HOLD (with --mode) and the reason to the ground station. A fence: when
the boat, coasting from its speed (the scenario's controller model, with a margin), would
leave the scenario's water or the `radius_m` around where it started, the run is cut short
(neutral; kept as far as it went) and the next begins once the boat has slowed.

Logs, as the session goes (`out_dir`): a CSV manoeuvre log per run from the telemetry (the
EKF state; commands = the servo outputs, SERVO_OUTPUT_RAW mapped with SERVOn_*), its time
the autopilot's time since boot, so the window printed for each run selects the same
stretch of the autopilot's own DataFlash log: `canalnav sysid DIR/*.csv`, or `canalnav sysid
LOG.BIN` (its runs found, or `--window T0:T1`); and `session.csv` with every control step.
"""

from __future__ import annotations

import csv
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from controller.errors import CanalnavError, InputError
from controller.geometry import wrap_angle

from bridge.onboard.lateness import Lateness
from bridge.onboard.open_water import RAY_MAX_M, OpenWater, coast_distance_m, run_length_m
from bridge.onboard.loop import (EXIT_GOAL, EXIT_INTERRUPTED, EXIT_STOPPED, MAV_SEVERITY_CRITICAL,
                            MAV_SEVERITY_INFO, MAV_SEVERITY_WARNING, BridgeOptions, link_fault,
                            prepare_link, safe_stop)

HOLD_S = 60.0
REPOSITION_THROTTLE_PCT = (30.0, 15.0)  # the second if the first leaves no room to turn
HEADING_GAIN_PCT_PER_DEG = 2.0
MAX_REPOSITION_STEER_PCT = 60.0
TURN_TOLERANCE_DEG = 5.0
AT_REST_MPS = 0.05
BRAKE_PCT = 30.0  # reverse thrust to slow down, at most
BRAKE_GAIN_PCT_PER_MPS = 300.0  # ... fading with the speed ahead
SLOW_MPS = 0.3
WAIT_LIMIT_S = 180.0
STOP_FACTOR = 1.5  # on the model's coasting distance
ENTRY_DEPTH_M = 10.0  # how far into open water the boat goes when it starts at its edge
MIN_HOLD_S = 20.0  # a level is held at least this long when the water is short
SHORT_WATER_SHARE = 0.9  # ... and the run planned to use at most this share of it
MAX_STEP_PERIODS = 5.0  # a late step moves the commands at most this many periods' worth


class _Ended(CanalnavError):
    """The session must end (failsafe): the reason, short."""


class _CutShort(Exception):
    """The run must end here (the fence): the reason."""


@dataclass
class RunRecord:
    """One run as it went: rows (autopilot time, state, servo commands), how it ended."""

    name: str
    maneuver: str
    use: str
    description: str
    rows: list = field(default_factory=list)
    cut_short: str = ""


@dataclass
class SessionResult:
    exit_code: int
    reason: str
    runs: list = field(default_factory=list)
    paths: list = field(default_factory=list)
    failsafes: list = field(default_factory=list)
    steps: int = 0  # control steps
    late_steps: int = 0  # of them late (the loop behind the clock)
    worst_late_s: float = 0.0


class ManeuverSession:
    """The runs on one prepared link (see the module docstring)."""

    def __init__(self, link, scenario, runs, options: BridgeOptions, out_dir: Path, *,
                 hold_s: float = HOLD_S, radius_m: float | None = None, console=sys.stderr):
        self.link = link
        self.clock = link.clock
        self.scenario = scenario
        self.runs = tuple(runs)
        self.options = options
        self.out_dir = Path(out_dir)
        self.hold_s = float(hold_s)
        self.radius_m = radius_m
        self.console = console
        self.period = options.control_period_s
        rates = tuple(float(r) for r in scenario.actuator_rates)
        self.rates = np.array([r if r > 0 else np.inf for r in rates])
        self._cmd = np.zeros(2)
        self._recording: RunRecord | None = None
        self._fenced = False  # a run is under way (its settling included): the fence is on
        self._last_logged = None
        self._servos = None
        self._start_xy = None
        self.water: OpenWater | None = None  # where the boat may go (from the start on)
        self._lengths: dict[str, float] = {}  # each run's way on the water, from the model
        self._shortest: dict[str, float] = {}  # ... with each level held MIN_HOLD_S
        self._run_hold_s = self.hold_s  # the hold of the run under way (shorter in short water)
        self._next_t = None
        self._last_tick = None
        self.lateness = Lateness(self.period)  # within runs: steps late, gaps
        self._session_fh = None
        self._session = None
        self.failsafes: list[str] = []

    # -- the session ----------------------------------------------------------------------
    def run(self) -> SessionResult:
        from bridge.onboard.loop import PreflightRefused

        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._plan()
        try:
            prepare_link(self.link, self.scenario, self.options, self.console)
        except PreflightRefused as exc:
            self._say("maneuvers: refused to start:\n  - " + "\n  - ".join(exc.reasons))
            return SessionResult(3, str(exc))
        self._servos = self._read_servo_params()
        self.link.request_streams(self.options.stream_rate_hz, messages=("SERVO_OUTPUT_RAW",))
        st = self.link.state
        self._start_xy = np.array([st.x, st.y])
        self.water = OpenWater(self.scenario.world, self._start_xy, self.radius_m)
        self._open_session_log()
        result = SessionResult(EXIT_GOAL, "manoeuvres done")
        try:
            for k, run in enumerate(self.runs):
                record = self._one(run)
                result.runs.append(record)
                result.paths.append(self._write(k, run, record))
            self._stop("manoeuvres done", MAV_SEVERITY_INFO)
        except _Ended as exc:
            self.failsafes.append(str(exc))
            self._stop(f"FAILSAFE {exc}", MAV_SEVERITY_CRITICAL)
            result.exit_code, result.reason = EXIT_STOPPED, str(exc)
        except KeyboardInterrupt:
            self._stop("FAILSAFE interrupted (Ctrl-C)", MAV_SEVERITY_CRITICAL)
            result.exit_code, result.reason = EXIT_INTERRUPTED, "interrupted (Ctrl-C)"
        except Exception as exc:
            try:
                self._stop(f"FAILSAFE bridge error: {exc}", MAV_SEVERITY_CRITICAL)
            except Exception:  # noqa: BLE001 - the original error matters more
                pass
            raise
        finally:
            if self._recording is not None and self._recording not in result.runs:
                result.runs.append(self._recording)
                result.paths.append(self._write(len(result.paths), None, self._recording))
            if self._session_fh is not None:
                self._session_fh.close()
        result.failsafes = list(self.failsafes)
        late = self.lateness
        result.steps, result.late_steps = late.steps, late.late_steps
        result.worst_late_s = late.worst_late_s
        if late.summary():
            self._say(f"maneuvers: {late.summary()}")
        return result

    def _plan(self) -> None:
        """How far each run takes the boat (the scenario's model, each level held `hold_s`),
        said before the session starts, so that each run can be placed where the water is
        long enough (`_reposition`)."""
        params = self.scenario.controller_params
        self._lengths = {run.name: run_length_m(run, params, self.hold_s, STOP_FACTOR)
                         for run in self.runs}
        if self.hold_s > MIN_HOLD_S:
            self._shortest = {run.name: run_length_m(run, params, MIN_HOLD_S, STOP_FACTOR)
                              for run in self.runs}
        self._say("maneuvers: the runs need about " + ", ".join(
            f"{name} {length:.0f} m" for name, length in self._lengths.items())
            + f" of straight water (each level held {self.hold_s:g} s)")

    def _read_servo_params(self):
        """SERVOn_FUNCTION for every output, then the calibration of the two that steer and
        throttle: the servo outputs' meaning, for the logs."""
        from controller.pwm import CommandChannels, servo_channel

        names = [f"SERVO{n}_FUNCTION" for n in range(1, 17)]
        params = self.link.wait_params_settled(names)
        chans = [servo_channel(params, f) for f in (26, 70)]
        if None in chans:
            self._say("note: no servo output with SERVOn_FUNCTION 26 and 70: the logs take the "
                      "commands sent instead of the servo outputs")
            return None
        params.update(self.link.wait_params_settled(
            [f"SERVO{n}_{k}" for n in chans for k in ("MIN", "MAX", "TRIM", "REVERSED")]))
        try:
            return CommandChannels.from_servo_params(params)
        except ValueError as exc:
            self._say(f"note: servo outputs not understood ({exc}); the logs take the commands "
                      "sent instead")
            return None

    def _one(self, run) -> RunRecord:
        from controller.identification.maneuvers import SurgeRun

        surge = isinstance(run, SurgeRun)
        if surge:
            levels = ", ".join(f"{v:.1f}" for v in run.throttle_pct)
            start = "rest" if not run.start_pct else f"steady {run.start_pct:.1f} %"
            text = (f"{run.maneuver} staircase nT = {levels} % from {start}, nS = 0, each level "
                    f"held {self.hold_s:g} s, on the boat")
            maneuver = run.maneuver
        else:
            text = (f"{run.heading_deg:g} deg/{run.steering_pct:g} % zigzag at nT = "
                    f"{run.throttle_pct:g} %, {run.overshoots} overshoots, on the boat")
            maneuver = "zigzag"
        self._say(f"maneuvers: {run.name}: {text}")
        self._reposition(run)
        record = RunRecord(run.name, maneuver, run.use, text)
        self._fenced = True
        try:
            if surge:
                self._surge(run, record)
            else:
                self._zigzag(run, record)
        except _CutShort as exc:
            self._fenced = False
            record.cut_short = str(exc)
            self._recording = None
            self._event(f"{run.name} cut short: {exc}")
            self._say(f"maneuvers: {run.name} cut short: {exc}")
            self._slow_down()
        self._fenced = False
        self._recording = None
        return record

    # -- the runs ---------------------------------------------------------------------------
    def _hold(self, target, seconds: float, record: RunRecord | None) -> None:
        self._recording = record
        end = self.clock.now() + seconds
        while self.clock.now() < end - 1e-9:
            self._tick(target)

    def _surge(self, run, record: RunRecord) -> None:
        hold = self._run_hold_s
        if run.start_pct:
            self._hold((run.start_pct, 0.0), hold, None)  # to steady state, not logged
        self._hold((run.start_pct, 0.0), run.lead_in_s, record)
        for level in run.throttle_pct:
            self._hold((level, 0.0), hold, record)

    def _zigzag(self, run, record: RunRecord) -> None:
        self._hold((run.throttle_pct, 0.0), self._run_hold_s, None)  # steady straight running
        self._hold((run.throttle_pct, 0.0), run.lead_in_s, record)
        psi0 = self.link.state.psi
        limit = math.radians(run.heading_deg)
        side, overshoots, reversed_at, t_end = 1.0, 0, False, None
        start = self.clock.now()
        while self.clock.now() - start < run.max_s:
            st = self._tick((run.throttle_pct, -side * run.steering_pct))
            dpsi = float(wrap_angle(st.psi - psi0))
            if side * dpsi >= limit:
                side, reversed_at = -side, True
            elif reversed_at and side * st.r > 0 and t_end is None:
                overshoots += 1  # the heading has turned back toward the new side
                reversed_at = False
                if overshoots >= run.overshoots:
                    t_end = self.clock.now() + run.tail_s
            if t_end is not None and self.clock.now() >= t_end:
                return

    # -- getting ready ----------------------------------------------------------------------
    def _reposition(self, run) -> None:
        """Get ready for `run`, not logged: out to open water first if the boat is at its
        edge; then turn (low throttle) to the heading with the most water ahead; hold each
        level shorter if even that is too short for the run; stop for a run from rest."""
        self._recording = None
        st = self.link.state
        here = np.array([st.x, st.y])
        if not self.water.ok(here)[0]:
            self._to_open_water(here, st.psi)
            st = self.link.state
            here = np.array([st.x, st.y])
        ray = self.water.best_heading(here, st.psi)
        need = self._lengths.get(run.name, 0.0)
        self._say(f"maneuvers: heading {math.degrees(ray.heading) % 360:.0f} deg, "
                  f"{ray.free_m:.0f} m of water ahead (the run needs about {need:.0f} m)")
        self._run_hold_s = self.hold_s
        shortest = self._shortest.get(run.name)
        if need > ray.free_m > 0 and shortest is not None:
            # the run's way grows about linearly with the hold: between the two worked out
            share = (SHORT_WATER_SHARE * ray.free_m - shortest) / max(need - shortest, 1e-6)
            self._run_hold_s = MIN_HOLD_S + max(0.0, share) * (self.hold_s - MIN_HOLD_S)
            self._say(f"maneuvers: {run.name}: each level held {self._run_hold_s:.0f} s instead "
                      f"of {self.hold_s:g} s to stay in the water"
                      + ("" if shortest <= SHORT_WATER_SHARE * ray.free_m else
                         f" (still too long, about {shortest:.0f} m: it will be cut short; "
                         "give it more water, or a shorter --hold)"))
        for throttle in REPOSITION_THROTTLE_PCT:
            try:
                self._turn_to(ray.heading, throttle)
                break
            except _CutShort as exc:
                self._say(f"maneuvers: turning at {throttle:g} %: {exc}; slowing down")
                self._slow_down()
        else:
            raise _Ended("no room to turn to the open water")
        from controller.identification.maneuvers import SurgeRun

        if isinstance(run, SurgeRun) and not run.start_pct:
            self._wait_speed(AT_REST_MPS)

    def _to_open_water(self, here: np.ndarray, psi: float) -> None:
        """The boat is where the runs may not go (at the water's edge, near a wall, outside
        the radius): turn to the nearest open water and go there at low throttle, unfenced,
        until the boat is `ENTRY_DEPTH_M` into it (braking then backs it out no further than
        the edge) and its coasting keeps it there."""
        why = self.water.why_not(here)
        ray = self.water.best_heading(here, psi)
        if not math.isfinite(ray.entry_m) or ray.free_m <= 0:
            raise _Ended(f"the boat is not in open water ({why}) and none is in reach "
                         f"within {RAY_MAX_M:g} m")
        self._say(f"maneuvers: the boat is not in open water ({why}): first "
                  f"{ray.entry_m:.0f} m on heading {math.degrees(ray.heading) % 360:.0f} deg to it")
        self._event(f"to open water: {why}")
        throttle = REPOSITION_THROTTLE_PCT[-1]
        start = self.clock.now()
        while self.clock.now() - start < WAIT_LIMIT_S:
            st = self.link.state
            back = np.array([st.x, st.y]) - ENTRY_DEPTH_M * np.array([math.cos(st.psi),
                                                                     math.sin(st.psi)])
            if self._fence(st) is None and self.water.ok(np.vstack([[st.x, st.y], back])).all():
                return
            err = float(wrap_angle(ray.heading - st.psi))
            nS = float(np.clip(-HEADING_GAIN_PCT_PER_DEG * math.degrees(err),
                               -MAX_REPOSITION_STEER_PCT, MAX_REPOSITION_STEER_PCT))
            self._tick((throttle, nS))
        raise _Ended(f"could not reach open water in {WAIT_LIMIT_S:g} s ({why})")

    def _turn_to(self, heading: float, throttle: float) -> None:
        """A proportional heading controller at `throttle`, fenced, until on `heading`."""
        start = self.clock.now()
        self._fenced = True
        try:
            while self.clock.now() - start < WAIT_LIMIT_S:
                st = self.link.state
                err = float(wrap_angle(heading - st.psi))
                if abs(math.degrees(err)) < TURN_TOLERANCE_DEG and abs(math.degrees(st.r)) < 1.0:
                    return
                # nS > 0 turns to port (heading decreasing): steer against the error
                nS = float(np.clip(-HEADING_GAIN_PCT_PER_DEG * math.degrees(err),
                                   -MAX_REPOSITION_STEER_PCT, MAX_REPOSITION_STEER_PCT))
                self._tick((throttle, nS))
        finally:
            self._fenced = False

    def _wait_speed(self, below_mps: float) -> None:
        """Slow the boat below `below_mps` (at most WAIT_LIMIT_S): reverse thrust fading with
        the speed (drag alone takes minutes for the last few cm/s), then neutral."""
        start = self.clock.now()
        st = self.link.state
        while self.clock.now() - start < WAIT_LIMIT_S and st.speed_mps >= below_mps:
            ahead = max(0.0, st.u)
            st = self._tick((-min(BRAKE_PCT, BRAKE_GAIN_PCT_PER_MPS * ahead), 0.0))
        while np.any(self._cmd != 0.0):  # back to neutral (at the actuators' rates)
            self._tick((0.0, 0.0))

    def _slow_down(self) -> None:
        self._wait_speed(SLOW_MPS)

    def _fence(self, st) -> str | None:
        """Why the boat must not go on (it would leave the water or the radius), or None."""
        speed = st.speed_mps
        reach = STOP_FACTOR * coast_distance_m(self.scenario.controller_params, speed)
        course = st.psi + math.atan2(st.v, st.u) if speed > 0.1 else st.psi
        d = np.linspace(0.0, max(reach, 0.0), max(2, int(reach / 2.0) + 2))
        pts = np.array([st.x, st.y]) + d[:, None] * np.array([math.cos(course), math.sin(course)])
        ok = self.water.ok(pts)
        if ok.all():
            return None
        p = pts[int(np.argmin(ok))]
        where = "the radius" if self.radius_m is not None and np.hypot(*(p - self._start_xy)) > \
            self.radius_m else "the water"
        return (f"coasting from {speed:.2f} m/s it would leave {where} near x {p[0]:.0f} "
                f"y {p[1]:.0f} m")

    # -- one control step -------------------------------------------------------------------
    def _tick(self, target):
        """Move the commands toward `target` at the actuators' rates over the time measured
        since the last step, send them, wait out the control period reading the link;
        failsafes and the fence. Returns the state.

        A step that comes late (the loop behind the clock: CPU load, a sped-up clock) moves
        the commands by the time that passed, so the manoeuvre keeps its timing; it is
        counted (`late_steps`), and said once, since the servo outputs then move in larger
        jumps than the actuators follow in one step."""
        target = np.clip(np.asarray(target, float), -100.0, 100.0)
        now = self.clock.now()
        elapsed = self.period if self._last_tick is None else now - self._last_tick
        self._last_tick = now
        warning = None
        if self._recording is not None:  # lateness within a run: between runs it does no harm
            warning = self.lateness.tick(now)[1]
        else:
            self.lateness.pause()
        if warning:
            self._event(warning)
            self._say(f"maneuvers: warning: {warning}: the servo outputs move in larger "
                      "jumps; lower --speedup, or give sysid --actuator-rates")
        step = self.rates * min(max(elapsed, 0.0), MAX_STEP_PERIODS * self.period)
        self._cmd = self._cmd + np.clip(target - self._cmd, -step, step)
        self.link.send_commands(*self._cmd)
        if self._next_t is None or self._next_t < now:
            self._next_t = now
        self._next_t += self.period
        self.link.idle(max(0.0, self._next_t - self.clock.now()))
        fault = link_fault(self.link) or self._param_fault()
        if fault is not None:
            raise _Ended(fault)
        st = self.link.state
        self._log_step(st)
        if self._fenced:
            reason = self._fence(st)
            if reason is not None:
                raise _CutShort(reason)
        if self._recording is not None and st.time_boot_s != self._last_logged:
            self._last_logged = st.time_boot_s
            self._recording.rows.append((st.time_boot_s, st.vector, self._servo_commands(st)))
        return st

    def _param_fault(self) -> str | None:
        from bridge.onboard import preflight

        changes = self.link.pop_param_changes()
        for c in changes:
            self._event(c.describe())
            self._say(f"maneuvers: {c.describe()}")
        if not changes:
            return None
        names = {c.name for c in changes}
        reasons = [r for r in preflight.refusals(self.link.heartbeat, self.link.params,
                                                 system_id=self.link.system_id,
                                                 requested_mode=self.options.mode or "MANUAL")
                   if any(n in r for n in names)]
        return f"parameter change: {reasons[0]}" if reasons else None

    def _servo_commands(self, st) -> tuple[float, float]:
        """The servo outputs in force at the state's time, as (nT, nS); else what was sent."""
        outs = self.link.servo_outputs
        if self._servos is None or not outs:
            return float(self._cmd[0]), float(self._cmd[1])
        pwm = None
        for t, values in reversed(outs):
            if t <= st.time_boot_s + 1e-6:
                pwm = values
                break
        if pwm is None:
            pwm = outs[0][1]
        return self._servos.to_commands({ch: pwm[ch - 1] for ch in range(1, 17)})

    # -- stopping and logs ------------------------------------------------------------------
    def _stop(self, reason: str, severity: int) -> None:
        held = safe_stop(self.link, self.options, reason, severity)
        self._cmd = np.zeros(2)
        self._event(reason)
        self._say(f"maneuvers: {reason}: neutral sent, overrides released{held}")

    def _open_session_log(self) -> None:
        self._session_fh = (self.out_dir / "session.csv").open("w", newline="")
        self._session = csv.writer(self._session_fh)
        self._session.writerow(["time_boot_s", "x_m", "y_m", "psi_rad", "u_mps", "v_mps",
                                "r_radps", "nT_cmd_pct", "nS_cmd_pct", "run", "event"])
        self._session_fh.flush()

    def _log_step(self, st) -> None:
        if self._session is None:
            return
        run = self._recording.name if self._recording is not None else ""
        self._session.writerow([repr(float(v)) for v in (st.time_boot_s, *st.vector, *self._cmd)]
                               + [run, ""])
        self._session_fh.flush()

    def _event(self, text: str) -> None:
        if self._session is None:
            return
        st = self.link.state
        t = repr(float(st.time_boot_s)) if st is not None else ""
        self._session.writerow([t] + [""] * 8 + ["", text])
        self._session_fh.flush()

    def _write(self, k: int, run, record: RunRecord) -> Path | None:
        """The run's CSV manoeuvre log (None if it has too few samples to be one)."""
        from controller.identification.logs import ManeuverLog, write_log

        if len(record.rows) < 2:
            self._say(f"maneuvers: {record.name}: nothing logged")
            return None
        t = np.array([r[0] for r in record.rows])
        states = np.array([r[1] for r in record.rows])
        commands = np.array([r[2] for r in record.rows], float)
        meta = {"maneuver": record.maneuver, "use": record.use,
                "description": record.description,
                "generator": "canalnav maneuvers --connect (EKF state and servo outputs over "
                             "MAVLink; time: the autopilot's, seconds since boot)",
                "window": f"{t[0]:.1f}:{t[-1]:.1f}"}
        if record.cut_short:
            meta["cut_short"] = record.cut_short
        log = ManeuverLog(t, states, commands, meta, source=record.name)
        path = self.out_dir / f"{record.name}.csv"
        write_log(path, log)
        self._say(f"{path}: {len(t)} samples, autopilot time {t[0]:.1f}-{t[-1]:.1f} s (sysid "
                  f"LOG.BIN --window {t[0]:.1f}:{t[-1]:.1f})"
                  + (" (held out)" if record.use == "heldout" else "")
                  + (f"; cut short: {record.cut_short}" if record.cut_short else ""))
        return path

    def _say(self, text: str) -> None:
        if self.console is not None:
            self.console.write(text + "\n")
            self.console.flush()


def run_on_boat(args, console=sys.stderr) -> int:
    """`canalnav maneuvers --connect URL --scenario FILE -o DIR`: wire it up and run."""
    from bridge.shared.clock import RealClock
    from bridge.onboard.link import AutopilotLink
    from bridge.onboard.loop import geodetic_origin, parse_origin
    from controller.identification.maneuvers import PAPER_RUNS, QUICK_RUNS, with_overshoots
    from scenarios.scenario_file import load_scenario

    if not args.scenario:
        raise InputError("maneuvers --connect: --scenario FILE is required (its water, the "
                         "actuator rates, the origin)")
    for name, value in (("--hold", args.hold), ("--radius", args.radius), ("--speedup", args.speedup)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive number, got {value!r}")
    scenario = load_scenario(args.scenario)
    options = BridgeOptions(
        connect=args.connect, scenario=args.scenario, arm=args.arm, mode=args.mode,
        system_id=args.system_id, target_system=args.target_system, speedup=args.speedup,
        ekf_timeout_s=args.ekf_timeout,
        origin=None if args.origin is None else parse_origin(args.origin))
    origin = geodetic_origin(scenario, options)
    runs = with_overshoots(QUICK_RUNS if args.quick else PAPER_RUNS,
                           getattr(args, "overshoots", None))
    key = None
    if args.signing_key:
        from bridge.shared.signing import load_signing_key

        key = load_signing_key(args.signing_key)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    link = AutopilotLink(args.connect, RealClock(args.speedup), system_id=args.system_id,
                         target_system=args.target_system, signing_key=key,
                         tlog_path=out / "mavlink.tlog", geodetic_origin=origin)
    try:
        session = ManeuverSession(link, scenario, runs, options, out, hold_s=args.hold,
                                  radius_m=args.radius, console=console)
        result = session.run()
    finally:
        link.close()
    print(f"canalnav maneuvers: {result.reason}; {sum(p is not None for p in result.paths)} "
          f"run log(s) in {out}")
    return result.exit_code
