"""The NMPC's segment slots: the nearest detected segments, padded with inactive ones.

The OCP has a fixed number of slots so it is built and compiled once. 16 by default: a canal
seen 50 m ahead and behind gives two walls of a few segments each (Hough merges straight
stretches), plus bends, quay corners and moored boats; 16 leaves room for that while each slot
adds 2 x Np constraint rows to every QP (16 slots: 800 rows).
"""

from __future__ import annotations

import numpy as np

from .errors import InputError

SLOT_FIELDS = ("x_c", "y_c", "theta", "length", "active")


def check_segments(segments) -> np.ndarray:
    """Segments as an (M, 4) array of (x_c, y_c, theta, length); clear errors for bad ones."""
    try:
        arr = np.asarray(segments, float)
    except (TypeError, ValueError):
        raise InputError("segments: expected an (M, 4) array of (x_c, y_c, theta, length)") from None
    if arr.size == 0:
        return np.zeros((0, 4))
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise InputError(f"segments: expected shape (M, 4), got {arr.shape}")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"segments: row {i} is not finite: {arr[i].tolist()}")
    short = arr[:, 3] <= 1e-6
    if short.any():
        i = int(np.argmax(short))
        raise InputError(f"segments: row {i} has zero or negative length {arr[i, 3]!r} m")
    return arr


def fill_segment_slots(segments, position, n_slots: int = 16,
                       range_m: float = np.inf) -> np.ndarray:
    """(n_slots, 5) rows (x_c, y_c, theta, length, active) from the segments nearest `position`.

    Segments farther than `range_m` are dropped; unused slots are inactive (all zeros).
    """
    arr = check_segments(segments)
    slots = np.zeros((n_slots, len(SLOT_FIELDS)))
    if len(arr) == 0:
        return slots
    distance = distance_to_segments(np.asarray(position, float)[:2], arr)
    order = np.argsort(distance, kind="stable")
    order = order[distance[order] <= range_m][:n_slots]
    slots[: len(order), :4] = arr[order]
    slots[: len(order), 4] = 1.0
    return slots


def distance_to_segments(point: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance (M,) from one point to each (x_c, y_c, theta, length) segment: the point's
    offset along the segment, clamped to its half length, and across it."""
    dx, dy = point[0] - segments[:, 0], point[1] - segments[:, 1]
    c, s = np.cos(segments[:, 2]), np.sin(segments[:, 2])
    along = np.abs(dx * c + dy * s)
    across = -dx * s + dy * c
    return np.hypot(np.maximum(along - segments[:, 3] / 2, 0.0), across)
