"""The detector's refit compiled (`wall_fit.c`): Hough's merged lines fitted to the occupied
cells, split at gaps and bends into chords, in one call per scan instead of a few hundred
numpy calls. C as the other perception kernels (see `controller.kernels`); the numpy twin is
`detection._refit_numpy`, the reference of the tests and the fallback where nothing can be
compiled."""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np

from ..kernels import Kernel, pointer

_i64, _ptr, _f64 = ctypes.c_int64, ctypes.c_void_p, ctypes.c_double

wall_fit_kernel = Kernel(Path(__file__).with_name("wall_fit.c"), {
    "wall_refit": (_i64, [_i64, _ptr, _i64, _ptr, *[_f64] * 8, _i64, _i64, _ptr])})
"""The compiled refit (call it: the library, or None for the numpy version)."""


def refit_compiled(lib, lines: list, xy: np.ndarray, cfg, capacity: int = 0) -> list:
    """`detection._refit` by the kernel: `lines` the merged lines longest first, each of
    some length; `xy` (N, 2) the cells' centroids. Returns the chords as (a, b) pairs.
    `capacity`: room for this many chords at first (0: enough for any usual scan); the
    kernel says when it needs more and is asked again."""
    xy = np.ascontiguousarray(xy, float)
    ends = np.ascontiguousarray(np.array(lines, float).reshape(-1, 4))
    reach = cfg.max_gap_m + cfg.gap_per_range * cfg.range_m
    capacity = capacity or len(xy) + 4 * len(ends) + 16
    while True:
        chords = np.empty((capacity, 4))
        n = lib.wall_refit(len(xy), pointer(xy), len(ends), pointer(ends), cfg.inlier_m,
                           float(reach), cfg.max_gap_m, cfg.gap_per_range, cfg.min_length_m,
                           cfg.cell_m, cfg.chord_tolerance_m, cfg.fit_band_m,
                           int(cfg.min_points), capacity, pointer(chords))
        if n == -1:
            capacity *= 4
            continue
        if n < 0:
            raise MemoryError("detection: the refit kernel ran out of memory")
        return [((ax, ay), (bx, by)) for ax, ay, bx, by in chords[:n].tolist()]
