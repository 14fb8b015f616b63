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
       "segments_cleaned", "perception_age_s", "blind", "slack_m", "status")
)
SEGMENT_COLUMNS = ("time_s", "x_c_m", "y_c_m", "theta_rad", "length_m")


class RunLog:
    """Context manager writing log.csv and segments.csv line by line."""

    def __init__(self, log_path: Path, segments_path: Path):
        self._paths = (Path(log_path), Path(segments_path))

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
                   view=None) -> None:
        """One control step; `width` is (canal width at the boat, smallest over the hull
        circles, offset from the middle), `metrics.CanalWidth.at`; `view` the perception
        feed's `PerceptionView` (rows cleaned away, age of the segments, blind)."""
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
        self._w.writerow(row)
        for s in np.asarray(segments, float).reshape(-1, 4):
            self._sw.writerow([f"{t:.3f}", *(repr(float(v)) for v in s)])
        self._fh.flush()
        self._sfh.flush()

    def __exit__(self, *exc) -> None:
        self._fh.close()
        self._sfh.close()
