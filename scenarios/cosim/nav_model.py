"""The navigation FMU's behaviour between FMI calls, shared by its FMI 2 and FMI 3 wrappers.

The wrappers only translate FMI onto `values` and these methods. The stack starts when
initialisation ends (the parameters and the boat's initial outputs are set by then) and
decides the command for t = 0 there. A master passes outputs on after the step, so each
step from t works one step ahead (`lookahead`): when t + h is an IMU instant the stack gets
the boat's outputs extrapolated to t + h, and when it is a control instant (every 0.1 s) the
controller decides for t + h, which the boat then holds from t + h as in `canalnav run`.
A failure never raises: it is a status, a reason for the FMU's log, and False from `step`
(the FMI error state).
"""

from __future__ import annotations

import csv
import json
import math
import traceback
from dataclasses import replace
from pathlib import Path

import numpy as np

from scenarios.cosim.nav_variables import (ACCEL_INPUTS, ACTUATOR_INPUTS, IMU_PERIOD_S,
                                           STATE_INPUTS, VARIABLES)
from scenarios.cosim.lookahead import BoatSample, ahead
from scenarios.cosim.navigation import STATUS_CODES, NavigationStack

SCENARIO_RESOURCE = "scenario.json"
"""The embedded scenario: the scenario file's document with the build's overrides applied."""

NO_CLEARANCE_M = 1e9  # the clearance output when no segment is seen (no inf across FMI)
LOG_COLUMNS = ("time_s", "est_x_m", "est_y_m", "est_psi_rad", "est_u_mps", "est_v_mps",
               "est_r_radps", "nT_cmd_pct", "nS_cmd_pct", "status", "slack_m", "clearance_m",
               "cross_track_m", "segments", "reason")


class NavigationModel:
    """Variable values by name, the navigation stack, and the step policy."""

    def __init__(self, resources: str | Path | None):
        self.resources = Path(resources) if resources else None
        self.values = {v.name: (v.start if v.start is not None else
                                (0 if v.kind == "integer" else 0.0)) for v in VARIABLES}
        self.stack: NavigationStack | None = None
        self.error: str | None = None  # why the FMU is in its error state
        self._imu_k = -1  # the last IMU instant fed to the stack
        self._before = None  # the boat's outputs at the last communication point
        self._log = None
        self._log_file = None

    def start(self) -> str | None:
        """Load the embedded scenario and build the stack; the reason when that fails."""
        from controller.errors import CanalnavError
        from scenarios.scenario_file import scenario_from_table

        source = str(self.resources / SCENARIO_RESOURCE) if self.resources else SCENARIO_RESOURCE
        try:
            document = json.loads(Path(source).read_text(encoding="utf-8"))
            scenario = scenario_from_table(document, source)
            if self.values["perception"]:
                scenario = replace(scenario, perception=self.values["perception"])
                if scenario.perception not in ("known-walls", "lidar"):
                    return self._fail(f"parameter perception: {scenario.perception!r} is not "
                                      f"one of known-walls, lidar")
            seed = int(self.values["seed"])
            self.stack = NavigationStack(scenario, self.values["controller"] or None,
                                         None if seed < 0 else seed)
            if self.values["log_path"]:
                path = Path(self.values["log_path"])
                path.parent.mkdir(parents=True, exist_ok=True)
                self._log_file = path.open("w", newline="")
                self._log = csv.writer(self._log_file)
                self._log.writerow(LOG_COLUMNS)
        except (CanalnavError, OSError, ValueError) as exc:
            return self._fail(f"cannot start the navigation: {exc}")
        try:
            now = self._sample()
            self.stack.start(now.state)
            self._imu_k = 0
            self._decide(0.0, now)
        except Exception as exc:  # noqa: BLE001 - the master must never see it raise
            return self._fail(_reason(exc, 0.0))
        return self.error

    def step(self, time_s: float, step_s: float) -> bool:
        """One communication step from `time_s` with the boat's outputs at `time_s`; False
        (and `error` set) when the FMU is, or now goes, into its error state."""
        if self.error is not None:
            return False
        ratio = IMU_PERIOD_S / step_s if step_s > 0 else math.inf
        if not (math.isfinite(ratio) and abs(ratio - round(ratio)) < 1e-6 and round(ratio) >= 1):
            self._fail(f"communication step {step_s:g} s: the navigation FMU needs a step "
                       f"that divides the IMU period {IMU_PERIOD_S:g} s (e.g. 0.01 or 0.005 s)")
            return False
        now, before = self._sample(), self._before
        self._before = now
        t_next = time_s + step_s
        k = round(t_next / IMU_PERIOD_S)
        if abs(t_next - k * IMU_PERIOD_S) > 1e-6 * step_s or k <= self._imu_k:
            return True  # the step ends between IMU instants: nothing is sampled
        try:
            command = (self.values["nT"], self.values["nS"])
            then = ahead(now, before, command, step_s)
            self.stack.sense(then.state, then.state_dot())
            self._imu_k = k
            if k % round(self.stack.control_period_s / IMU_PERIOD_S) == 0:
                self._decide(k * IMU_PERIOD_S, then)
        except Exception as exc:  # noqa: BLE001 - the master must never see it raise
            self._fail(_reason(exc, t_next))
            return False
        return self.error is None

    def _sample(self) -> BoatSample:
        v = self.values
        return BoatSample(np.array([v[n] for n in STATE_INPUTS], float),
                          np.array([v[n] for n in ACCEL_INPUTS], float),
                          np.array([v[n] for n in ACTUATOR_INPUTS], float))

    def _decide(self, t: float, boat: BoatSample) -> None:
        """The controller's decision at control instant `t` into the outputs and the log."""
        v = self.values
        period = self.stack.control(t, boat.state, boat.actuators)
        v["nT"], v["nS"] = (float(c) for c in period.command)
        v["status"] = int(period.status)
        v["slack"] = period.slack_m
        v["clearance"] = period.clearance_m if math.isfinite(period.clearance_m) \
            else NO_CLEARANCE_M
        v["cross_track"] = period.cross_track_m
        if self._log is not None:
            self._log.writerow([f"{t:.3f}", *(repr(float(x)) for x in period.estimate),
                                *(repr(float(x)) for x in period.command), period.status,
                                repr(period.slack_m), repr(period.clearance_m),
                                repr(period.cross_track_m), period.segments, period.reason])
            self._log_file.flush()
        if period.status == STATUS_CODES["failed"]:
            self._fail(self.stack.failed)

    def _fail(self, reason: str) -> str:
        self.error = reason
        self.values["status"] = STATUS_CODES["failed"]
        self.values["nT"] = self.values["nS"] = 0.0
        return reason

    def close(self) -> None:
        if self._log_file is not None:
            self._log_file.close()
            self._log_file = None
        if self.stack is not None:
            self.stack.close()
            self.stack = None


def _reason(exc: Exception, time_s: float) -> str:
    """An exception as one line: what, where in our code, and when."""
    last = traceback.extract_tb(exc.__traceback__)[-1]
    return (f"navigation failed at t = {time_s:.2f} s: {type(exc).__name__}: {exc} "
            f"({Path(last.filename).name}:{last.lineno})")
