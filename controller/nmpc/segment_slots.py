"""The NMPC's segment slots: the detected segments nearest the planned path, padded with
inactive ones.

The OCP has a fixed number of slots so it is built and compiled once; each slot adds 2 x Np
constraint rows to every QP (16 slots: 800 rows). Which segments fill them matters more than
how many there are: Hough splits a wall into pieces, and on the Pohang run half the steps see
more than 16 (up to 31). Ranked by distance to the boat, the 16 nearest include pieces behind
the stern and leave out the walls 20-50 m ahead that the later stages run along. They are
therefore ranked by distance to the planned path (the warm start, or the reference at a cold
start) plus a little of the distance from the boat (`NEAR_FIRST_PER_M`), which keeps the
walls along the whole horizon; the step reports how many were left out and how close the
nearest of them came to the plan (`SegmentSelection`).
Why 16: `canalnav bench nmpc --segment-slots N` (the bench's bend is walls in 4 m pieces, up
to 35 within 50 m) gave RTI 0.70 / 0.76 / 0.89 / 1.00 ms a step with 8 / 16 / 24 / 32 slots
and the same closed-loop track within 3 cm; the nearest segment left out came 6.2 / 6.9 /
7.5 m from the plan with 8 / 16 / 24, about the reach of a constraint (R_b + d_p plus the
hull circles' 2 m offset: 7 m). On the Pohang run (LiDAR, d_p = 4 m, reach 9 m) 16 slots
left segments out at 43 % of the steps, the nearest 5.7 m from the plan, and 24 slots gave
the same run (min clearance 6.43 m and J_c 12.9e3 both), 0.03 ms a step dearer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..kernels import pointer
from .path_geometry import geometry_kernel, slot_distances

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
        raise InputError(f"segments: row {i} has zero or negative length {arr[i, 3]:g} m")
    return arr


@dataclass(frozen=True)
class SegmentSelection:
    """The slots handed to the OCP, and what did not fit."""

    slots: np.ndarray  # (n_slots, 5) rows (x_c, y_c, theta, length, active)
    dropped: int  # segments within range left out for want of a slot
    dropped_nearest_m: float  # the closest of those to the planned path (inf: none dropped)


NEAR_FIRST_PER_M = 0.05
"""Of two segments as close to the plan, the one nearer the boat ranks first: 1 m of
distance to the plan weighs as much as 20 m of distance from the boat. The near future
matters most, and the next steps' solves see the farther walls as the boat comes closer."""


def select_segments(segments, position, n_slots: int = 16, range_m: float = np.inf,
                    path=None) -> SegmentSelection:
    """Fill `n_slots` slots with the segments within `range_m` of `position`, nearest the
    planned `path` (K, 2) first (nearest `position` when there is no path)."""
    return select_checked(check_segments(segments), position, n_slots, range_m, path)


def select_checked(arr: np.ndarray, position, n_slots: int = 16, range_m: float = np.inf,
                   path=None) -> SegmentSelection:
    """`select_segments` for segments `check_segments` has already checked."""
    slots = np.zeros((n_slots, len(SLOT_FIELDS)))
    if len(arr) == 0:
        return SegmentSelection(slots, 0, np.inf)
    position = np.asarray(position, float)
    if path is None:
        points = position[None, :2]
    else:
        path = np.asarray(path, float).reshape(-1, 2)
        points = np.empty((len(path) + 1, 2))
        points[0], points[1:] = position[:2], path
    to_boat, to_plan = slot_distances(points, arr)
    in_range = np.flatnonzero(to_boat <= range_m)
    to_plan = to_plan[in_range]
    order = np.argsort(to_plan + NEAR_FIRST_PER_M * to_boat[in_range], kind="stable")
    kept = in_range[order[:n_slots]]
    slots[: len(kept), :4] = arr[kept]
    slots[: len(kept), 4] = 1.0
    left_out = order[n_slots:]
    nearest = float(to_plan[left_out].min()) if len(left_out) else np.inf
    return SegmentSelection(slots, len(left_out), nearest)


def kept_in_place(slots: np.ndarray, prev: np.ndarray) -> np.ndarray:
    """`slots` (n, 5) rearranged so that each segment also in last step's `prev` keeps the
    slot it had there, the new ones in the free slots in order: the order of the slots does
    not change the OCP, and unchanged slots let the feedback keep the prepared constraints.
    `slots` itself when none is kept or two rows match one. By the compiled kernel
    (`path_geometry.c`), or `kept_in_place_numpy` where there is none."""
    lib = geometry_kernel()
    if lib is None:
        return kept_in_place_numpy(slots, prev)
    slots = np.ascontiguousarray(slots, float)
    prev = np.ascontiguousarray(prev, float)
    out = np.empty_like(slots)
    scratch = np.empty(2 * len(slots), np.int64)
    if len(prev) != len(slots) or not lib.keep_slots(len(slots), pointer(slots), pointer(prev),
                                                     pointer(scratch), pointer(out)):
        return slots
    return out


def kept_in_place_numpy(slots: np.ndarray, prev: np.ndarray) -> np.ndarray:
    """`kept_in_place`'s numpy twin: last step's rows looked up in a dict."""
    slot_at: dict = {}
    for j, row in enumerate(prev.tolist()):
        if row[4] > 0:
            slot_at.setdefault(tuple(row[:4]), j)
    old_at, matched, rest = [], [], []
    for i, row in enumerate(slots.tolist()):
        if row[4] > 0:
            j = slot_at.get(tuple(row[:4]))
            if j is None:
                rest.append(i)
            else:
                old_at.append(j)
                matched.append(i)
    if not old_at or len(set(old_at)) < len(old_at):  # none kept, or a duplicate
        return slots
    out = np.zeros_like(slots)
    out[old_at] = slots[matched]
    taken = set(old_at)
    free = [j for j in range(len(slots)) if j not in taken]
    out[free[: len(rest)]] = slots[rest]
    return out


def fill_segment_slots(segments, position, n_slots: int = 16, range_m: float = np.inf,
                       path=None) -> np.ndarray:
    """(n_slots, 5) rows (x_c, y_c, theta, length, active): `select_segments`' slots."""
    return select_segments(segments, position, n_slots, range_m, path).slots


def distance_to_segments(point: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance (M,) from one point to each (x_c, y_c, theta, length) segment."""
    return slot_distances(np.asarray(point, float)[None, :2], segments)[0]
