"""The bridge's per-step CSV log and its one-line console status, written as the run goes.

`steps.csv` has a row per control step (time, reported and predicted state, commands, PWM
sent, the measured one-way link delay and the state's age since the autopilot made it, the
scan's age and blindness, the vessels tracked, the rows perception cleaned away, the water
estimate, status) and a row per event (failsafe, resume, waiting, parameter change, goal)
with the state columns empty; `segments.csv` the segments each step used, `tracks.csv` the
vessel tracks (as `canalnav run` writes them). All are flushed after every row, so a crash or
a pulled plug loses nothing before it. With a `BridgeViz` the same steps go to run.mcap and/or
the live Foxglove view (`scenarios.results.mcap_log`), on the same clock as steps.csv.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

STATE = ("x_m", "y_m", "psi_rad", "u_mps", "v_mps", "r_radps")
STEP_COLUMNS = (
    ("time_s", "ekf_time_s", "state_age_s", "link_delay_s")
    + STATE + tuple(f"pred_{n}" for n in STATE)
    + ("nT_cmd_pct", "nS_cmd_pct", "throttle_pwm_us", "steering_pwm_us", "segments",
       "nearest_segment_m", "scan_age_s", "blind", "tracks", "segments_cleaned",
       "current_n_mps", "current_e_mps", "bias_u_mps2", "bias_v_mps2", "bias_r_radps2",
       "current_used_n_mps", "current_used_e_mps", "solve_ms", "slack_m", "mode", "armed",
       "status")
)
SEGMENT_COLUMNS = ("time_s", "x_c_m", "y_c_m", "theta_rad", "length_m")


@dataclass
class Step:
    """What one control step saw and did."""

    time_s: float
    ekf_time_s: float
    state_age_s: float
    link_delay_s: float
    state: np.ndarray
    predicted: np.ndarray
    command: np.ndarray
    pwm: tuple[int | None, int | None]  # throttle, steering
    segments: np.ndarray
    nearest_segment_m: float
    solve_ms: float
    slack_m: float
    mode: str
    armed: bool
    status: str
    view: object = None  # controller.perception.feed.PerceptionView of this step
    water: object = None  # controller.water_estimator.WaterEstimate of this step
    cloud: object = None  # the LiDAR cloud of this step (N, 3) body frame, for the viewer
    plan: object = None  # the controller's predicted horizon (K, >=3), for the viewer
    current_used: object = None  # (2,) the current the controller was given (NED, m/s)


BRIDGE_FIGURES = (
    "time_s", "ekf_time_s", "state_age_s", "link_delay_s", "u_mps", "v_mps", "r_radps",
    "speed_mps", "nT_cmd_pct", "nS_cmd_pct", "throttle_pwm_us", "steering_pwm_us", "segments",
    "nearest_segment_m", "scan_age_s", "blind", "tracks", "segments_cleaned", "current_n_mps",
    "current_e_mps", "solve_ms", "slack_m", "armed",
)


class BridgeViz:
    """The bridge's steps in Foxglove: the EKF pose as `boat`, the cloud, segments, plan,
    hull circles, tracks, the position as a LocationFix (the bridge always has an origin),
    and the figures of steps.csv; events (failsafes, waiting) as the `status` text."""

    def __init__(self, options, origin, lidar_mounts=(), hull_radius_m: float = 3.0,
                 separation_m: float | None = None):
        from scenarios.results import foxglove_messages as fm
        from scenarios.results.mcap_log import VizLog

        self.log = VizLog(options, BRIDGE_FIGURES, ("mode", "status"), name="canalnav-bridge")
        self.origin = tuple(origin)
        self.lidars = fm.lidar_frames(lidar_mounts)
        self.hull_radius_m = hull_radius_m
        self.separation_m = separation_m

    @property
    def live_url(self):
        return self.log.live_url

    def step(self, s: Step) -> None:
        from scenarios.results.foxglove_messages import finite

        log, t = self.log, s.time_s
        log.frames(t, s.predicted, None, self.lidars)
        if s.cloud is not None:
            log.cloud(t, s.cloud)
        log.segments(t, s.segments)
        log.plan(t, s.plan, self.hull_radius_m, self.separation_m)
        view = s.view
        if view is not None and view.tracks:
            log.tracks(t, view.tracks)
        log.fix(t, s.state[0], s.state[1], self.origin)
        water = s.water
        values = {"time_s": t, "ekf_time_s": s.ekf_time_s, "state_age_s": s.state_age_s,
                  "link_delay_s": s.link_delay_s, "u_mps": s.state[3], "v_mps": s.state[4],
                  "r_radps": s.state[5], "speed_mps": math.hypot(s.state[3], s.state[4]),
                  "nT_cmd_pct": s.command[0], "nS_cmd_pct": s.command[1],
                  "throttle_pwm_us": math.nan if s.pwm[0] is None else s.pwm[0],
                  "steering_pwm_us": math.nan if s.pwm[1] is None else s.pwm[1],
                  "segments": len(np.asarray(s.segments).reshape(-1, 4)),
                  "nearest_segment_m": s.nearest_segment_m,
                  "scan_age_s": math.nan if view is None else view.age_s,
                  "blind": math.nan if view is None else int(view.blind),
                  "tracks": 0 if view is None else len(view.tracks),
                  "segments_cleaned": 0 if view is None else sum(view.dropped.values()),
                  "current_n_mps": math.nan if water is None else water.current_ne[0],
                  "current_e_mps": math.nan if water is None else water.current_ne[1],
                  "solve_ms": s.solve_ms, "slack_m": s.slack_m, "armed": int(s.armed)}
        values = {k: finite(v) for k, v in values.items()}
        log.figures(t, {**values, "mode": s.mode, "status": s.status})
        log.end_step(t)

    def event(self, time_s: float, status: str, mode: str = "") -> None:
        self.log.figures(time_s, {"time_s": time_s, "mode": mode, "status": status})

    def close(self) -> None:
        self.log.close()


class StepLog:
    """steps.csv and segments.csv in a folder (or nowhere with `folder=None`)."""

    def __init__(self, folder: Path | None, viz: BridgeViz | None = None):
        self._files = []
        self.viz = viz
        if folder is None:
            self._w = self._sw = self._tw = None
            return
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        from scenarios.loop.run_log import TRACK_COLUMNS

        fh = (folder / "steps.csv").open("w", newline="")
        sfh = (folder / "segments.csv").open("w", newline="")
        tfh = (folder / "tracks.csv").open("w", newline="")
        self._files = [fh, sfh, tfh]
        self._w, self._sw, self._tw = csv.writer(fh), csv.writer(sfh), csv.writer(tfh)
        self._w.writerow(STEP_COLUMNS)
        self._sw.writerow(SEGMENT_COLUMNS)
        self._tw.writerow(TRACK_COLUMNS)
        self._flush()

    def step(self, s: Step) -> None:
        if self.viz is not None:
            self.viz.step(s)
        if self._w is None:
            return
        nums = [s.time_s, s.ekf_time_s, s.state_age_s, s.link_delay_s, *s.state, *s.predicted,
                *s.command]
        row = [_num(v) for v in nums]
        row += ["" if p is None else int(p) for p in s.pwm]
        row += [len(s.segments), _num(s.nearest_segment_m)]
        view = s.view
        if view is None:
            row += ["", "", "", ""]
        else:
            row += [_num(view.age_s), int(view.blind), len(view.tracks), sum(view.dropped.values())]
        if s.water is None:
            row += [""] * 5
        else:
            row += [_num(v) for v in (*s.water.current_ne, *s.water.bias)]
        row += ["", ""] if s.current_used is None else [_num(v) for v in s.current_used]
        row += [f"{s.solve_ms:.3f}", _num(s.slack_m), s.mode, int(s.armed), s.status]
        self._w.writerow(row)
        for seg in np.asarray(s.segments, float).reshape(-1, 4):
            self._sw.writerow([_num(s.time_s), *(_num(v) for v in seg)])
        if view is not None and view.tracks:
            from scenarios.loop.run_log import track_row

            for tr in view.tracks:
                self._tw.writerow(track_row(s.time_s, tr))
        self._flush()

    def event(self, time_s: float, status: str, mode: str = "", armed: bool | None = None) -> None:
        if self.viz is not None:
            self.viz.event(time_s, status, mode)
        if self._w is None:
            return
        row = [""] * len(STEP_COLUMNS)
        row[0] = _num(time_s)
        row[-3], row[-2], row[-1] = mode, "" if armed is None else int(armed), status
        self._w.writerow(row)
        self._flush()

    def _flush(self) -> None:
        for fh in self._files:
            fh.flush()

    def close(self) -> None:
        if self.viz is not None:
            self.viz.close()
            self.viz = None
        for fh in self._files:
            fh.close()
        self._files = []
        self._w = self._sw = self._tw = None


def _num(v) -> str:
    v = float(v)
    return repr(v) if math.isfinite(v) else ""


def status_line(s: Step) -> str:
    """One console line: time, mode, arming, position, speed, commands, nearest wall, the
    measured link delay and the state's age (since the autopilot made it), the vessels
    tracked, the water estimate, blindness."""
    x, y, psi, u, v, _ = s.state
    near = f"{s.nearest_segment_m:5.1f} m" if math.isfinite(s.nearest_segment_m) else "  --   "
    extra = ""
    if s.view is not None:
        extra += f"  boats {len(s.view.tracks)}" + ("  BLIND" if s.view.blind else "")
    if s.water is not None:
        extra += f"  current {math.hypot(*s.water.current_ne):4.2f} m/s"
    return (f"t {s.time_s:7.1f} s  {s.mode:<8} {'ARMED' if s.armed else 'disarmed':<8} "
            f"x {x:8.1f} y {y:8.1f} hdg {math.degrees(psi) % 360:5.1f}  {math.hypot(u, v):4.2f} m/s  "
            f"nT {s.command[0]:6.1f} nS {s.command[1]:6.1f} %  wall {near}  "
            f"delay {s.link_delay_s * 1e3:4.0f} ms  age {s.state_age_s * 1e3:4.0f} ms{extra}  {s.status}")
