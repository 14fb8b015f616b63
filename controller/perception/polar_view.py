"""What each LiDAR on the boat sees, as polar images over bearing bins: the nearest return
per bin, and how steeply the own hull rises per bin (`clusters.free_space` asks both, about
a cluster's ends, on most scans with a vessel in view).

Compiled (`polar_view.c`, C as the other perception kernels, see `controller.kernels`) around
numpy's float32 arctan2, so the bins are numpy's bit for bit: every return's bin once a scan
(one arctan2 over every viewpoint at once), then ranges only in the few bins asked, instead
of whole images by a dozen numpy passes and a slow `ufunc.at` per viewpoint.
`nearest_numpy` and `hull_slope_numpy` (the whole images) are the twins: the tests'
reference and the fallback where nothing can be compiled.
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np

from ..kernels import Kernel, pointer

N_BINS = 1440  # bins of a quarter degree (the beams: ~0.35 deg apart)
_SCALE, _HALF = np.float32(N_BINS / (2 * math.pi)), np.float32(N_BINS / 2)

_i64, _ptr, _f64, _f32 = ctypes.c_int64, ctypes.c_void_p, ctypes.c_double, ctypes.c_float
_OFFSETS = (None, [_i64, _ptr, _i64, _i64, _i64, *[_ptr] * 4])
_NEAREST_AT = (None, [_i64, _ptr, _i64, _i64, _ptr, _f64, _f64, ctypes.c_int, _i64, _ptr, _i64,
                      _ptr])
polar_kernel = Kernel(Path(__file__).with_name("polar_view.c"), {
    "polar_offsets_f32": _OFFSETS, "polar_offsets_f64": _OFFSETS,
    "polar_hull_offsets": (None, [_i64, _ptr, _i64, *[_ptr] * 4]),
    "polar_bins": (None, [_i64, _ptr, _f32, _f32, _i64, _ptr]),
    "polar_hull_slope_at": (None, [_i64, _ptr, _ptr, _f64, _f64, _f64, _i64, _ptr, _i64,
                                   _ptr]),
    "polar_nearest_at_f32": _NEAREST_AT, "polar_nearest_at_f64": _NEAREST_AT})
"""The compiled passes (call it: the library, or None for the numpy twins)."""

_SCRATCH: dict = {}


def _scratch(name: str, size: int, dtype) -> np.ndarray:
    """A reused buffer of `size` items (not zeroed): a scan's offsets are a few hundred kB,
    and fresh ones would cost a page fault per 4 kB every scan."""
    buf = _SCRATCH.get(name)
    if buf is None or len(buf) < size:
        buf = _SCRATCH[name] = np.empty(max(size, 1), dtype)
    return buf[:size]


def bearing_bin(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bearing bins of body-frame points (float32 arctan: a third of the float64 time)."""
    a = np.arctan2(np.asarray(y, np.float32), np.asarray(x, np.float32))
    a *= _SCALE
    a += _HALF
    return np.minimum(a.astype(np.intp), N_BINS - 1)


def _bins(lib, fx: np.ndarray, fy: np.ndarray, shape) -> np.ndarray:
    """The bearing bins (int16, `shape`) of float32 offsets: numpy's arctan2, then the
    kernel's binning (`bearing_bin`'s arithmetic)."""
    angle = _scratch("angle", len(fx), np.float32)
    np.arctan2(fy, fx, out=angle)
    out = np.empty(shape, np.int16)
    lib.polar_bins(len(fx), pointer(angle), _SCALE, _HALF, N_BINS, pointer(out))
    return out


class OccluderView:
    """The returns that can hide something (N, 2: body-frame x, y) as each viewpoint (V, 2+)
    sees them: `nearest(k, bins)` is the squared range of the nearest in each bin seen from
    viewpoint k (inf: none), as `nearest_numpy(...)[k, bins]`. The bins of every return are
    found once; ranges only for the returns in the bins asked."""

    def __init__(self, occluders: np.ndarray, viewpoints: np.ndarray):
        self.occluders = np.asarray(occluders)
        self.viewpoints = np.asarray(viewpoints, float)
        p = self.occluders
        self._lib = polar_kernel()
        if self._lib is None or p.dtype not in (np.float32, np.float64) or p.ndim != 2:
            self._lib = None
            self._image = nearest_numpy(p, self.viewpoints)
        self._bins = None  # (V, N) int16, made when first asked

    def nearest(self, k: int, bins: np.ndarray) -> np.ndarray:
        bins = np.ascontiguousarray(bins, np.int64)
        if self._lib is None:
            return self._image[k, bins]
        out = np.full(len(bins), np.inf)
        p, n = self.occluders, len(self.occluders)
        if not n or not len(bins):
            return out
        if self._bins is None:
            self._bins = self._occluder_bins()
        vx, vy = self.viewpoints[k, :2].tolist()
        size = p.itemsize
        at = self._lib.polar_nearest_at_f32 if p.dtype == np.float32 \
            else self._lib.polar_nearest_at_f64
        at(n, p.__array_interface__["data"][0], p.strides[0] // size, p.strides[1] // size,
           pointer(self._bins[k]), vx, vy, int(vx == 0.0 and vy == 0.0), len(bins),
           pointer(bins), N_BINS, pointer(out))
        return out

    def _occluder_bins(self) -> np.ndarray:
        lib, p = self._lib, self.occluders
        v = self.viewpoints[:, :2]
        nv, n = len(v), len(p)
        vx, vy = np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1])
        fx, fy = _scratch("fx", nv * n, np.float32), _scratch("fy", nv * n, np.float32)
        size = p.itemsize
        offsets = lib.polar_offsets_f32 if p.dtype == np.float32 else lib.polar_offsets_f64
        offsets(n, p.__array_interface__["data"][0], p.strides[0] // size,
                p.strides[1] // size, nv, pointer(vx), pointer(vy), pointer(fx), pointer(fy))
        return _bins(lib, fx, fy, (nv, n))


class HullView:
    """The own hull's returns (H, 3: body-frame x, y, height up) as each viewpoint (V, 3:
    x, y, height) sees them: `slope(k, bins)` is the steepest rise (height over range) of
    those in each bin seen from viewpoint k (-inf: none, or its height not known), as
    `hull_slope_numpy(...)[k, bins]`. The bins of every return are found once; ranges only
    for the returns in the bins asked (a few a scan, of 1440)."""

    def __init__(self, hull_returns: np.ndarray, viewpoints: np.ndarray):
        self.returns = np.ascontiguousarray(hull_returns, float).reshape(-1, 3)
        self.viewpoints = np.asarray(viewpoints, float).reshape(-1, 3)
        self._lib = polar_kernel()
        self._bins = None  # (V, H) int16, made when first asked
        if self._lib is None:
            self._image = hull_slope_numpy(self.returns, self.viewpoints)

    def slope(self, k: int, bins: np.ndarray) -> np.ndarray:
        bins = np.ascontiguousarray(bins, np.int64)
        vx, vy, vz = self.viewpoints[k].tolist()
        if self._lib is None:
            return self._image[k, bins]
        out = np.full(len(bins), -np.inf)
        h, n = self.returns, len(self.returns)
        if not n or not math.isfinite(vz) or not len(bins):
            return out
        if self._bins is None:
            self._bins = self._hull_bins()
        self._lib.polar_hull_slope_at(n, pointer(h), pointer(self._bins[k]), vx, vy, vz,
                                      len(bins), pointer(bins), N_BINS, pointer(out))
        return out

    def _hull_bins(self) -> np.ndarray:
        lib, h, v = self._lib, self.returns, self.viewpoints
        nv, n = len(v), len(h)
        vx, vy = np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1])
        fx, fy = _scratch("fx", nv * n, np.float32), _scratch("fy", nv * n, np.float32)
        lib.polar_hull_offsets(n, pointer(h), nv, pointer(vx), pointer(vy), pointer(fx),
                               pointer(fy))
        return _bins(lib, fx, fy, (nv, n))


def nearest_numpy(occluders: np.ndarray, viewpoints: np.ndarray) -> np.ndarray:
    """(V, bins) the squared range of the nearest return per bearing bin seen from each
    viewpoint (inf: none): `OccluderView`'s numpy twin, the whole image."""
    return np.stack([_polar_ranges(occluders - v[:2]) if v[:2].any()
                     else _polar_ranges(occluders) for v in np.asarray(viewpoints, float)])


def _polar_ranges(xy: np.ndarray) -> np.ndarray:
    """(bins,) the squared range of the nearest return per bearing bin (inf: none)."""
    img = np.full(N_BINS, np.inf)
    if len(xy):
        x, y = xy[:, 0], xy[:, 1]
        np.minimum.at(img, bearing_bin(x, y), (x * x + y * y).astype(float))
    return img


def hull_slope_numpy(hull_returns: np.ndarray, viewpoints: np.ndarray) -> np.ndarray:
    """(V, bins) the own hull's steepest rise per bearing bin seen from each viewpoint
    (-inf: none): `HullView`'s numpy twin, the whole image."""
    v = np.asarray(viewpoints, float).reshape(-1, 3)
    out = np.full((len(v), N_BINS), -np.inf)
    h = np.asarray(hull_returns, float).reshape(-1, 3)
    for k, (vx, vy, vz) in enumerate(v.tolist()):
        if len(h) and math.isfinite(vz):
            dx, dy = h[:, 0] - vx, h[:, 1] - vy
            r = np.hypot(dx, dy)
            near = r > 1e-3
            np.maximum.at(out[k], bearing_bin(dx[near], dy[near]), (h[near, 2] - vz) / r[near])
    return out
