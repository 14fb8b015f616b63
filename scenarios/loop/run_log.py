"""The per-step run log, written and flushed as the run goes (nothing lost on interrupt).

`log.csv` has one row per control step; `segments.csv` one row per segment the controller
saw at that step. Units are in the column names.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

STATE = ("x_m", "y_m", "psi_rad", "u_mps", "v_mps", "r_radps")
LOG_COLUMNS = (
    ("time_s",)
    + tuple(f"true_{n}" for n in STATE)
    + tuple(f"est_{n}" for n in STATE)
    + ("nT_cmd_pct", "nS_cmd_pct", "dnT_pctps", "dnS_pctps", "nT_actual_pct", "nS_actual_pct",
       "clearance_bow_m", "clearance_stern_m", "cross_track_m", "canal_width_m",
       "canal_width_min_hull_m", "centre_offset_m", "solve_ms", "segments", "segments_dropped",
       "segments_cleaned", "perception_age_s", "blind", "slack_m", "status",
       "current_true_n_mps", "current_true_e_mps", "current_est_n_mps", "current_est_e_mps",
       "current_sigma_n_mps", "current_sigma_e_mps", "bias_u_mps2", "bias_v_mps2",
       "bias_r_radps2", "tracks", "rules", "elastic_segments", "elastic_vessels",
       "current_used_n_mps", "current_used_e_mps", "surge_over_mps")
)
SEGMENT_COLUMNS = ("time_s", "x_c_m", "y_c_m", "theta_rad", "length_m")
TRACK_COLUMNS = ("time_s", "id", "x_m", "y_m", "v_north_mps", "v_east_mps", "heading_rad",
                 "length_m", "width_m", "moving", "sigma_position_m")
VESSEL_COLUMNS = ("time_s", "name", "x_m", "y_m", "psi_rad")


def track_row(t: float, tr) -> list:
    """One tracks.csv row (TRACK_COLUMNS) for a track at time `t`."""
    cov = np.asarray(tr.covariance, float).reshape(4, 4)
    return [f"{t:.3f}", tr.id, *(repr(float(v)) for v in (
        *tr.position, *tr.velocity, tr.heading_rad, tr.length_m, tr.width_m)),
        int(bool(getattr(tr, "moving", True))),
        repr(float(np.sqrt(max(0.5 * (cov[0, 0] + cov[1, 1]), 0.0))))]


class RunLog:
    """Context manager writing log.csv and segments.csv line by line."""

    def __init__(self, log_path: Path, segments_path: Path):
        self._paths = (Path(log_path), Path(segments_path))
        self._tracks = None  # tracks.csv and vessels.csv, opened at the first vessel

    def __enter__(self) -> "RunLog":
        self._fh = self._paths[0].open("w", newline="")
        self._sfh = self._paths[1].open("w", newline="")
        self._w = csv.writer(self._fh)
        self._sw = csv.writer(self._sfh)
        self._w.writerow(LOG_COLUMNS)
        self._sw.writerow(SEGMENT_COLUMNS)
        return self

    def write_step(self, t, true_state, est_state, command, rate, actuators, clearance,
                   cross_track, solve_ms, decision, segments, width=(np.inf, np.inf, 0.0),
                   view=None, current=(0.0, 0.0)) -> None:
        """One control step; `width` is (canal width at the boat, smallest over the hull
        circles, offset from the middle), `metrics.CanalWidth.at`; `view` the perception
        feed's `PerceptionView` (rows cleaned away, age of the segments, blind); `current`
        the true current at the boat (the estimate comes with the decision's stats)."""
        row = [f"{t:.3f}"]
        row += [repr(float(v)) for v in true_state]
        row += [repr(float(v)) for v in est_state]
        row += [repr(float(v)) for v in (*command, *rate, *actuators, *clearance, cross_track,
                                         *width)]
        cleaned = sum(view.dropped.values()) if view is not None else 0
        age = view.age_s if view is not None else 0.0
        blind = int(view.blind) if view is not None else 0
        row += [f"{solve_ms:.3f}", len(segments), int(decision.stats.get("segments_dropped", 0)),
                cleaned, f"{age:.3f}", blind, repr(float(decision.slack_m)), decision.status]
        row += [repr(float(v)) for v in current]
        water = decision.stats.get("water")  # the controller's water estimate, if it has one
        if water is None:
            row += [""] * 7
        else:
            row += [repr(float(v)) for v in (*water.current_ne, *water.current_sigma, *water.bias)]
        row += [len(view.tracks) if view is not None else 0, decision.stats.get("rules", "")]
        elastic = decision.stats.get("elastic")  # the NMPC's soft obstacle rows (h units)
        row += ["", ""] if elastic is None else [repr(float(v)) for v in elastic]
        used = decision.stats.get("current_used")  # what the controller was given
        row += ["", ""] if used is None else [repr(float(v)) for v in used]
        over = decision.stats.get("surge_over")  # the plan above its surge ceiling (NMPC)
        row.append("" if over is None else repr(float(over)))
        self._w.writerow(row)
        for s in np.asarray(segments, float).reshape(-1, 4):
            self._sw.writerow([f"{t:.3f}", *(repr(float(v)) for v in s)])
        self._fh.flush()
        self._sfh.flush()

    def write_tracks(self, t, tracks, vessels) -> None:
        """The vessel tracks the controller saw (tracks.csv) and the true vessels
        (vessels.csv, (name, pose) pairs) at this step."""
        if self._tracks is None:
            folder = self._paths[0].parent
            self._tracks = [(folder / name).open("w", newline="")
                            for name in ("tracks.csv", "vessels.csv")]
            self._tw = [csv.writer(f) for f in self._tracks]
            self._tw[0].writerow(TRACK_COLUMNS)
            self._tw[1].writerow(VESSEL_COLUMNS)
        for tr in tracks:
            self._tw[0].writerow(track_row(t, tr))
        for name, pose in vessels:
            self._tw[1].writerow([f"{t:.3f}", name, *(repr(float(v)) for v in pose)])
        for f in self._tracks:
            f.flush()

    def __exit__(self, *exc) -> None:
        self._fh.close()
        self._sfh.close()
        for f in self._tracks or ():
            f.close()
