"""The compiled crops of a LiDAR cloud (`cloud_crop.c`): detection's crop (indices, x and
y; or the rows) and the tracker's split of its crop into occluders, band points and the own
hull's returns; and detection's occupancy grid (`occupancy.c`). Loaded once per process; None where nothing
can be compiled, and the callers (`detection._crop`, `tracking.split_crop`) then use their
numpy twins."""

from __future__ import annotations

import ctypes
from pathlib import Path

from ..kernels import Kernel

_i64, _ptr, _f64 = ctypes.c_int64, ctypes.c_void_p, ctypes.c_double
_CROP = (_i64, [_i64, _ptr, _i64, _i64, *[_f64] * 8, *[_ptr] * 4])
_SPLIT = (None, [_i64, _ptr, _i64, _i64, _f64, _f64, ctypes.c_int, _f64, _f64, _f64,
                 *[_ptr] * 4])

crop_kernel = Kernel(Path(__file__).with_name("cloud_crop.c"), {
    "crop_f32": _CROP, "crop_f64": _CROP, "split_f32": _SPLIT, "split_f64": _SPLIT})
"""The compiled crops (call it: the library, or None for the numpy versions)."""

occupancy_kernel = Kernel(Path(__file__).with_name("occupancy.c"), {
    "occupancy": (_i64, [_i64, _ptr, _ptr, _i64, _f64, _f64, *[_ptr] * 6]),
    "grid_at": (None, [_i64, _ptr, _i64, _f64, _f64, _ptr, _ptr])})
"""The compiled occupancy grid and lookup of a grid at points (call it: the library, or
None for the numpy versions)."""
