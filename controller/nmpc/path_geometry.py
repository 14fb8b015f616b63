"""The compiled geometry of the NMPC's step (`path_geometry.c`): points at arc lengths, the
closest point and the path frame of points (`WaypointPath.at`, `.project`, `.frame`), the
forced slack (`slack_reference.forced_slack_at`, and per stage `forced_slack`), the walls
abeam (`slack_reference.walls_abeam`), the segment slots' ranking and
keeping (`slot_distances`, `segment_slots.kept_in_place`), the
passage sweep's walk (`passage.walk_slabs`) and the rays and sight lines of the
blind-opening rule (`blind_openings.side_rays`, `rays_crossing`): the largest numpy costs of
a step's set-up after the QP. Loaded once per process; None where nothing can be compiled,
and the callers then run their numpy twins."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from ..geometry import segments_cross
from ..kernels import Kernel, pointer

_i64, _ptr, _f64 = ctypes.c_int64, ctypes.c_void_p, ctypes.c_double

geometry_kernel = Kernel(Path(__file__).with_name("path_geometry.c"), {
    "path_frame": (None, [_i64, _ptr, _ptr, _i64, _ptr, _ptr, _ptr, _ptr, _f64, _f64, _ptr,
                          _ptr]),
    "forced_slack_at": (_i64, [_i64, _ptr, _ptr, _ptr, _i64, _ptr, _f64, _f64, _ptr, _ptr]),
    "walls_abeam": (None, [_i64] + [_ptr] * 4 + [_i64] + [_ptr] * 5 + [_f64, _ptr, _ptr]),
    "slot_distances": (None, [_i64, _ptr, _i64, _ptr, _ptr, _ptr, _ptr, _ptr]),
    "walk_slabs": (_i64, [_i64, _ptr, _ptr, _i64] + [_f64] * 5 + [_ptr] * 4),
    "rays_crossing": (None, [_i64, _ptr, _i64, _ptr, _i64, _ptr, _ptr, ctypes.c_int, _ptr]),
    "forced_slack_stages": (None, [_i64, _ptr, _ptr, _f64, _f64, _i64, _ptr, _i64] + [_ptr] * 5
                            + [_i64, _ptr, _f64, _f64, _ptr, _ptr]),
    "path_points": (None, [_i64, _ptr, _i64] + [_ptr] * 7),
    "path_project": (_f64, [_f64, _f64, _i64] + [_ptr] * 4 + [_f64, _f64, _ptr]),
    "keep_slots": (_i64, [_i64] + [_ptr] * 4),
    "side_rays": (None, [_i64, _ptr, _i64] + [_ptr] * 5 + [_f64] * 4 + [_i64] + [_ptr] * 4)})
"""The compiled path geometry (call it: the library, or None for the numpy versions)."""


def rays_crossing(p, q, a, b, closed: bool = False) -> np.ndarray:
    """(n,) bool: which lines p[i] -> q[i] ((n, 2), or p one point (2,) for all) cross any
    wall a[j] -> b[j] ((m, 2)); `closed`: touching counts too. By the kernel, or
    `rays_crossing_numpy` where there is none."""
    lib = geometry_kernel()
    if lib is None:
        return rays_crossing_numpy(p, q, a, b, closed)
    q = np.ascontiguousarray(q, float).reshape(-1, 2)
    p = np.ascontiguousarray(p, float)
    a, b = np.ascontiguousarray(a, float), np.ascontiguousarray(b, float)
    out = np.empty(len(q), np.uint8)
    lib.rays_crossing(len(q), pointer(p), 0 if p.ndim == 1 else 2, pointer(q), len(a),
                      pointer(a), pointer(b), int(closed), pointer(out))
    return out.view(bool)


def rays_crossing_numpy(p, q, a, b, closed: bool = False) -> np.ndarray:
    """`rays_crossing`'s numpy twin."""
    q = np.asarray(q, float).reshape(-1, 2)
    p = np.broadcast_to(np.asarray(p, float), q.shape)
    return segments_cross(p, q, np.asarray(a, float), np.asarray(b, float), closed).any(axis=1)


def slot_distances(points, segments) -> tuple[np.ndarray, np.ndarray]:
    """Each segment's ((M, 4) rows x_c, y_c, theta, length) distance from points[0] (the
    boat) and from the nearest of all the points ((K, 2): the boat, then its plan): the
    ranking of `segment_slots.select_checked`. By the kernel, or `slot_distances_numpy`."""
    lib = geometry_kernel()
    if lib is None:
        return slot_distances_numpy(points, segments)
    p = np.ascontiguousarray(points, float).reshape(-1, 2)
    seg = np.ascontiguousarray(segments, float).reshape(-1, 4)
    c, s = np.cos(seg[:, 2]), np.sin(seg[:, 2])
    to_boat, to_plan = np.empty(len(seg)), np.empty(len(seg))
    lib.slot_distances(len(p), pointer(p), len(seg), pointer(seg), pointer(c), pointer(s),
                       pointer(to_boat), pointer(to_plan))
    return to_boat, to_plan


def slot_distances_numpy(points, segments) -> tuple[np.ndarray, np.ndarray]:
    """`slot_distances`' numpy twin: the (K, M) distances, their first row and least."""
    points = np.asarray(points, float).reshape(-1, 2)
    segments = np.asarray(segments, float).reshape(-1, 4)
    dx = points[:, 0:1] - segments[:, 0]
    dy = points[:, 1:2] - segments[:, 1]
    c, s = np.cos(segments[:, 2]), np.sin(segments[:, 2])
    along = np.abs(dx * c + dy * s)
    across = -dx * s + dy * c
    distance = np.hypot(np.maximum(along - segments[:, 3] / 2, 0.0), across)
    return distance[0], distance.min(axis=0)
