"""Perception's own output check: segments that no wall could give are dropped and counted.

A detector sees noise, a driver delivers garbage now and then: a segment of no length, NaN
coordinates, the same segment twice, one hundreds of metres long or far outside the sensors'
range. None of that is bad input from a user, so none of it may end a run: `clean_segments`
keeps the plausible rows and says how many of each kind it dropped, for the step's stats and
the log. (The NMPC still checks what a caller passes by hand, and raises on it.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..errors import InputError

DROP_REASONS = ("malformed", "non_finite", "degenerate", "duplicate", "too_long", "out_of_range")


@dataclass(frozen=True)
class CleaningConfig:
    """What a plausible segment is. Lengths and ranges in metres, angles in radians.

    min_length_m: shorter is a point, not a wall (the detector's own minimum is 1 m).
    max_length_m: longer than any wall a 120 m sensor can see in one scan (2 x its range).
    max_range_m: a segment whose nearest point lies farther from the boat cannot be a
    detection of this scan (the sensors reach 120 m).
    duplicate_m, duplicate_rad: two rows this close in centre, length and direction are one.
    """

    min_length_m: float = 0.05
    max_length_m: float = 250.0
    max_range_m: float = 150.0
    duplicate_m: float = 1e-3
    duplicate_rad: float = 1e-3

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value <= 0:
                raise InputError(f"segment cleaning: {f.name} must be a positive number, "
                                 f"got {value!r}")
        if self.min_length_m >= self.max_length_m:
            raise InputError("segment cleaning: min_length_m must be below max_length_m")


@dataclass(frozen=True)
class CleanedSegments:
    """The segments kept, (M, 4) rows (x_c, y_c, theta, length), and the count dropped per
    reason (`DROP_REASONS`; "malformed": the whole input was not an (M, 4) array)."""

    segments: np.ndarray
    dropped: dict

    @property
    def dropped_total(self) -> int:
        return int(sum(self.dropped.values()))


def _empty() -> np.ndarray:
    return np.zeros((0, 4))


def clean_segments(segments, position=None,
                   config: CleaningConfig = CleaningConfig()) -> CleanedSegments:
    """Drop what cannot be a wall; never raises for what the data holds.

    `position` (x, y) of the boat, for the range check (None: no range check). The order of
    the rows kept is the input's.
    """
    dropped = dict.fromkeys(DROP_REASONS, 0)
    try:
        arr = np.array(segments, dtype=float)
    except (TypeError, ValueError):
        dropped["malformed"] = 1
        return CleanedSegments(_empty(), dropped)
    if arr.size == 0:
        return CleanedSegments(_empty(), dropped)
    if arr.ndim == 1 and arr.size == 4:
        arr = arr.reshape(1, 4)
    if arr.ndim != 2 or arr.shape[1] != 4:
        dropped["malformed"] = 1
        return CleanedSegments(_empty(), dropped)
    keep = np.isfinite(arr).all(axis=1)
    dropped["non_finite"] = int(len(arr) - keep.sum())
    length = np.where(keep, arr[:, 3], 0.0)
    degenerate = keep & (length < config.min_length_m)
    dropped["degenerate"] = int(degenerate.sum())
    keep &= ~degenerate
    too_long = keep & (length > config.max_length_m)
    dropped["too_long"] = int(too_long.sum())
    keep &= ~too_long
    if position is not None and keep.any():
        p = np.asarray(position, float).reshape(-1)[:2]
        if np.isfinite(p).all():
            far = np.zeros(len(arr), bool)
            far[keep] = _distance(p, arr[keep]) > config.max_range_m
            dropped["out_of_range"] = int(far.sum())
            keep &= ~far
    rows = np.flatnonzero(keep)
    if len(rows) > 1:
        unique = _first_of_duplicates(arr[rows], config)
        dropped["duplicate"] = int(len(rows) - unique.sum())
        rows = rows[unique]
    return CleanedSegments(arr[rows], dropped)


def _distance(point: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distance from one point to each (x_c, y_c, theta, length) segment."""
    dx, dy = point[0] - segs[:, 0], point[1] - segs[:, 1]
    c, s = np.cos(segs[:, 2]), np.sin(segs[:, 2])
    along = np.maximum(np.abs(dx * c + dy * s) - 0.5 * segs[:, 3], 0.0)
    return np.hypot(along, -dx * s + dy * c)


def _first_of_duplicates(segs: np.ndarray, config: CleaningConfig) -> np.ndarray:
    """(M,) mask keeping the first of each group of rows that are the same segment: the same
    centre and length within `duplicate_m`, the same undirected direction within
    `duplicate_rad`."""
    theta = (segs[:, 2] + np.pi / 2) % np.pi - np.pi / 2  # undirected
    if len(segs) > 512:  # garbage in bulk: exact duplicates on a grid, O(M log M)
        q = np.round(np.column_stack([segs[:, 0], segs[:, 1], segs[:, 3]]) / config.duplicate_m)
        key = np.column_stack([q, np.round(theta / config.duplicate_rad)])
        _, first = np.unique(key, axis=0, return_index=True)
        mask = np.zeros(len(segs), bool)
        mask[first] = True
        return mask
    near = (np.abs(segs[:, None, 0] - segs[None, :, 0]) <= config.duplicate_m) \
        & (np.abs(segs[:, None, 1] - segs[None, :, 1]) <= config.duplicate_m) \
        & (np.abs(segs[:, None, 3] - segs[None, :, 3]) <= config.duplicate_m)
    turn = np.abs(theta[:, None] - theta[None, :])
    near &= np.minimum(turn, np.pi - turn) <= config.duplicate_rad
    earlier = np.tril(near, k=-1)  # row i duplicates an earlier row j < i
    return ~earlier.any(axis=1)
