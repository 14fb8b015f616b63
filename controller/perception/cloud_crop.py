"""The compiled crops of a LiDAR cloud (`cloud_crop.c`): detection's crop (indices, x and
y; or the rows) and the tracker's split of its crop into occluders, band points and the own
hull's returns; and detection's occupancy grid (`occupancy.c`). Loaded once per process; None where nothing can be compiled, and the
callers (`detection._crop`, `tracking.split_crop`) then use their numpy twins."""

from __future__ import annotations

import ctypes
from pathlib import Path

from ..kernels import load_kernel

_SOURCE = Path(__file__).with_name("cloud_crop.c")
_KERNEL: list = []


def crop_kernel():
    """The compiled crop (None: the numpy version), loaded once per process."""
    if not _KERNEL:
        lib = load_kernel(_SOURCE)
        if lib is not None:
            i64, ptr, f64 = ctypes.c_int64, ctypes.c_void_p, ctypes.c_double
            for f in (lib.crop_f32, lib.crop_f64):
                f.restype = i64
                f.argtypes = [i64, ptr, i64, i64, *[f64] * 8, *[ptr] * 3]
            for f in (lib.crop_rows_f32, lib.crop_rows_f64):
                f.restype = i64
                f.argtypes = [i64, ptr, i64, i64, *[f64] * 8, ptr]
            for f in (lib.split_f32, lib.split_f64):
                f.restype = None
                f.argtypes = [i64, ptr, i64, i64, f64, f64, ctypes.c_int, f64, f64, f64,
                              *[ptr] * 4]
        _KERNEL.append(lib)
    return _KERNEL[0]




_OCCUPANCY: list = []


def occupancy_kernel():
    """The compiled occupancy grid (None: the numpy version), loaded once per process."""
    if not _OCCUPANCY:
        lib = load_kernel(Path(__file__).with_name("occupancy.c"))
        if lib is not None:
            lib.occupancy.restype = ctypes.c_int64
            lib.occupancy.argtypes = [ctypes.c_int64, ctypes.c_void_p, ctypes.c_void_p,
                                      ctypes.c_int64, ctypes.c_double, ctypes.c_double,
                                      *[ctypes.c_void_p] * 6]
        _OCCUPANCY.append(lib)
    return _OCCUPANCY[0]
