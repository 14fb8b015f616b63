"""The tracker's clustering grid compiled (`cluster_cells.c`): the points' cells less the
lone returns, and each component's members, in two calls per scan instead of a few dozen
numpy calls over every point. C as the other perception kernels (see `controller.kernels`);
the numpy twins are `clusters.sociable_points_numpy` and `clusters.cluster_members_numpy`,
the reference of the tests and the fallback where nothing can be compiled."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from ..kernels import Kernel, pointer

_i64, _ptr, _f64 = ctypes.c_int64, ctypes.c_void_p, ctypes.c_double

cluster_kernel = Kernel(Path(__file__).with_name("cluster_cells.c"), {
    "sociable_points": (_i64, [_i64, _ptr, _f64, _f64, _i64, _ptr, _i64, _f64, *[_ptr] * 4]),
    "cluster_members": (_i64, [_i64, _ptr, _ptr, _ptr, _i64, _ptr, _i64, _i64, *[_ptr] * 3])})
"""The compiled clustering passes (call it: the library, or None for the numpy versions)."""


def sociable_points_compiled(lib, xy: np.ndarray, r: float, cell: float, n: int,
                             walls=None, wall_cell: float = 1.0):
    """`clusters.sociable_points_numpy` by the kernel: (xy, i, j, grid)."""
    xy = np.ascontiguousarray(xy, np.float64)
    m = len(xy)
    out, i, j = np.empty((m, 2)), np.empty(m, np.int64), np.empty(m, np.int64)
    grid = np.empty((n, n), np.uint8)
    if walls is not None:
        walls = np.ascontiguousarray(walls, np.uint8)
    k = lib.sociable_points(m, pointer(xy), float(r), 1.0 / cell, n,
                            None if walls is None else pointer(walls),
                            0 if walls is None else walls.shape[0], 1.0 / wall_cell,
                            pointer(out), pointer(i), pointer(j), pointer(grid))
    if k < 0:
        raise MemoryError("clusters: the grid kernel ran out of memory")
    return out[:k], i[:k], j[:k], grid


def cluster_members_compiled(lib, i: np.ndarray, j: np.ndarray, labels: np.ndarray, root,
                             n_labels: int, min_points: int):
    """`clusters.cluster_members_numpy` by the kernel: (count, good, order, first)."""
    labels = np.ascontiguousarray(labels, np.int32)
    root_p = None if root is None else np.ascontiguousarray(root, np.int64)
    m = len(i)
    count, start = np.empty(n_labels, np.int64), np.empty(n_labels, np.int64)
    order = np.empty(m, np.int64)
    total = lib.cluster_members(m, pointer(i), pointer(j), pointer(labels), labels.shape[1],
                                None if root_p is None else pointer(root_p), n_labels,
                                int(min_points), pointer(count), pointer(start),
                                pointer(order))
    if total < 0:
        raise MemoryError("clusters: the members kernel ran out of memory")
    good = np.flatnonzero(count >= min_points)
    return count, good, order[:total], start[good]
