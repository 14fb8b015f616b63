"""The compiled geometry of the NMPC's step (`path_geometry.c`): the path frame of points
(`WaypointPath.frame`) and the forced slack (`slack_reference.forced_slack_at`), the two
largest numpy costs of a step's set-up after the QP. Loaded once per process; None where
nothing can be compiled, and the callers then run their numpy twins."""

from __future__ import annotations

import ctypes
from pathlib import Path

from ..kernels import Kernel

_i64, _ptr, _f64 = ctypes.c_int64, ctypes.c_void_p, ctypes.c_double

geometry_kernel = Kernel(Path(__file__).with_name("path_geometry.c"), {
    "path_frame": (None, [_i64, _ptr, _ptr, _i64, _ptr, _ptr, _ptr, _ptr, _f64, _f64, _ptr,
                          _ptr]),
    "forced_slack_at": (_i64, [_i64, _ptr, _ptr, _ptr, _i64, _ptr, _f64, _f64, _ptr, _ptr])})
"""The compiled path geometry (call it: the library, or None for the numpy versions)."""
