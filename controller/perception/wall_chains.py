"""The tracker's confident walls compiled (`wall_chains.c`): which segments, alone or chained
with others, are longer than any vessel, in one call per scan instead of two dozen numpy
calls. C as the other perception kernels (see `controller.kernels`); the numpy twin is
`clusters.chained_walls_numpy`, the reference of the tests and the fallback where nothing
can be compiled."""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np

from ..kernels import Kernel, pointer

_i64, _ptr, _f64 = ctypes.c_int64, ctypes.c_void_p, ctypes.c_double

chain_kernel = Kernel(Path(__file__).with_name("wall_chains.c"), {
    "chained_walls": (ctypes.c_int, [_i64, _ptr, _ptr, _ptr, _f64, _f64, _f64, _ptr])})
"""The compiled chains (call it: the library, or None for the numpy version)."""


def chained_walls_compiled(lib, s: np.ndarray, cfg) -> np.ndarray:
    """`clusters.chained_walls_numpy` by the kernel, for (M, 4) segments `s` (M >= 1); the
    cosines and sines are numpy's, as the twin takes them."""
    s = np.ascontiguousarray(s, np.float64)
    cs, sn = np.cos(s[:, 2]), np.sin(s[:, 2])
    wall = np.empty(len(s), np.uint8)
    if lib.chained_walls(len(s), pointer(s), pointer(cs), pointer(sn),
                         float(cfg.chain_gap_m ** 2), math.radians(cfg.chain_angle_deg),
                         float(cfg.max_vessel_length_m), pointer(wall)):
        raise MemoryError("clusters: the wall chains kernel ran out of memory")
    return wall.view(bool)
