"""LiDAR wall detection (paper §III-A): a merged point cloud in, line segments out.

    crop by height (drop water, quay tops, buildings) and by x, y (drop own hull and wake)
    -> 2-D occupancy grid -> OpenCV HoughLinesP -> merge collinear, overlapping pieces
    -> refit each line to its points (total least squares), split it at gaps
    -> split bent walls into chords (Douglas-Peucker), join faces meeting at corners
    -> segments L_i = (x_c, y_c, theta, length) in the inertial frame (eq. line)

The Hough transform finds which points lie on which wall; the refit makes the segment as
accurate as the points, not as coarse as the grid. Long straight walls come out as a few long
segments; a bend as a chain of chords within `chord_tolerance_m` of the curve (the NMPC
then takes the segments nearest the boat). Every threshold is in `DetectionConfig`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..kernels import pointer
from . import opencv
from .cloud_crop import crop_kernel, occupancy_kernel
from .wall_fit import refit_compiled, wall_fit_kernel


@dataclass(frozen=True)
class DetectionConfig:
    """Thresholds of the detection pipeline, SI units, heights above the waterline (up).

    The height band keeps the wall face between the water and the lowest quay top: below
    `min_height_m` are water returns and speckle, above `max_height_m` are quay tops,
    buildings, trees and bridge decks. Keep `max_height_m` below the lowest quay in the
    canal (the paper's walls stand 1-3 m above the water).
    """

    # Crop (body frame).
    min_height_m: float = 0.15
    max_height_m: float = 0.9
    range_m: float = 60.0  # keep |x|, |y| <= this; the NMPC's horizon reaches ~50 m
    hull_x_m: tuple[float, float] = (-4.6, 4.6)  # own hull and cabin (7.9 m boat) + margin
    hull_half_width_m: float = 1.9  # 2.6 m breadth + margin
    wake_length_m: float = 14.0  # behind hull_x_m[0]: spray and foam in the wake ...
    wake_half_width_m: float = 3.3  # ... kept short: a wall right astern is still a wall
    # Occupancy grid and Hough transform.
    cell_m: float = 0.2
    hough_theta_deg: float = 1.0  # the refit, not the accumulator, sets the final angle
    hough_votes: int = 5  # accumulator threshold (cells on one line)
    min_length_m: float = 1.0  # shorter pieces and segments are dropped
    max_gap_m: float = 2.0  # largest gap bridged along one wall next to the boat ...
    gap_per_range: float = 0.12  # ... growing by this many metres per metre of range, as the
    # returns of a wall seen at a glancing angle thin out with distance (6.8 m at 40 m)
    # Merging and refit.
    merge_angle_deg: float = 3.0
    merge_offset_m: float = 0.3  # perpendicular distance between collinear pieces
    inlier_m: float = 0.25  # points this close to a line belong to it
    min_points: int = 3  # fewest occupied cells behind a segment
    chord_tolerance_m: float = 0.05  # a chord strays at most this far from a bent wall
    fit_band_m: float = 0.1  # the final fit of a chord uses the points this close to it
    corner_join_m: float = 0.6  # ends of faces meeting at an angle this close are joined

    def __post_init__(self) -> None:
        positive = ("cell_m", "hough_theta_deg", "range_m", "min_length_m", "max_gap_m",
                    "merge_angle_deg", "merge_offset_m", "inlier_m", "chord_tolerance_m",
                    "fit_band_m", "corner_join_m")
        for name in positive + ("gap_per_range", "wake_length_m", "wake_half_width_m",
                                "hull_half_width_m"):
            value = getattr(self, name)
            ok = isinstance(value, (int, float)) and math.isfinite(value)
            if not ok or value < 0 or (name in positive and value == 0):
                kind = "positive" if name in positive else "non-negative"
                raise InputError(f"detection config: {name} must be a {kind} number, got {value!r}")
        if not self.min_height_m < self.max_height_m:
            raise InputError("detection config: min_height_m must be below max_height_m")
        if self.hough_votes < 1 or self.min_points < 2:
            raise InputError("detection config: hough_votes >= 1 and min_points >= 2 needed")
        if self.range_m / self.cell_m > 4096:
            raise InputError(f"detection config: grid of {2 * self.range_m / self.cell_m:.0f} "
                             "cells a side is too large; raise cell_m or lower range_m")


DEFAULT = DetectionConfig()


def detect_segments(points, pose, config: DetectionConfig = DEFAULT) -> np.ndarray:
    """Wall segments seen in one merged cloud.

    points: (N, 3) x, y, z in the body frame (x forward, y starboard, z down, origin on the
    waterline). pose: the boat's (x, y, psi) in the inertial NED frame. Returns an (M, 4)
    float array of segments (x_c, y_c, theta, length) in the inertial frame, theta in
    [-pi/2, pi/2), longest first; (0, 4) when nothing is found. Rows with NaN or inf are
    dropped with a warning that counts them.
    """
    cloud = _checked_cloud(points)
    x, y, psi = _checked_pose(pose)
    body = _fit_segments(_cropped_xy(cloud, config), config)
    if not len(body):
        return np.zeros((0, 4))
    c, s = math.cos(psi), math.sin(psi)
    xc = x + c * body[:, 0] - s * body[:, 1]
    yc = y + s * body[:, 0] + c * body[:, 1]
    theta = _half_turn(body[:, 2] + psi)
    out = np.column_stack([xc, yc, theta, body[:, 3]])
    return out[np.argsort(-out[:, 3], kind="stable")]


def with_settings(settings, base: DetectionConfig = DEFAULT) -> DetectionConfig:
    """`base` with NAME=VALUE settings (`--detect-set`); an InputError names a bad one."""
    import dataclasses


    fields = {f.name: f for f in dataclasses.fields(base)}
    changes = {}
    for text in settings:
        name, sep, value = text.partition("=")
        name = name.strip()
        if not sep or name not in fields:
            raise InputError(f"--detect-set {text!r}: expected NAME=VALUE with NAME one of "
                             f"{', '.join(sorted(fields))}")
        old = getattr(base, name)
        try:
            if isinstance(old, tuple):
                new = tuple(float(v) for v in value.split(","))
                if len(new) != len(old):
                    raise ValueError
            else:
                new = type(old)(float(value)) if not isinstance(old, bool) else value == "true"
        except ValueError:
            raise InputError(f"--detect-set {text!r}: {name} takes "
                             f"{'numbers a,b' if isinstance(old, tuple) else 'a number'} "
                             f"(now {old!r})") from None
        changes[name] = new
    try:
        return dataclasses.replace(base, **changes)
    except (ValueError, InputError) as exc:
        raise InputError(f"--detect-set: {exc}") from None


ASTERN_MPS = -0.1
"""Below this surge speed (m/s) the boat goes astern (`for_surge`)."""


def for_surge(config: DetectionConfig, surge_mps: float) -> DetectionConfig:
    """The config to crop with at a surge speed: going astern there is no wake behind the
    hull, and what lies behind is where the boat goes, so the wake's box (which would hide
    the wall it backs towards) is not cropped."""
    if surge_mps < ASTERN_MPS and config.wake_length_m > 0.0:
        return replace(config, wake_length_m=0.0)
    return config


def crop_mask(points, config: DetectionConfig = DEFAULT) -> np.ndarray:
    """Which points of a clean (N, 3) body-frame cloud the detector keeps (paper Fig. (c))."""
    p = np.asarray(points)
    keep = np.zeros(len(p), bool)
    keep[_crop_index(p, config)] = True
    return keep


def _crop_index(p: np.ndarray, config: DetectionConfig) -> np.ndarray:
    """Indices of the points `crop_mask` keeps, in order."""
    return _crop(p, config)[0]


def crop_xy(points, config: DetectionConfig = DEFAULT):
    """The points of a clean (N, 3) body-frame cloud that `crop_mask` keeps: their indices
    (ascending) and x and y (the cloud's dtype), without a mask over the whole cloud."""
    return _crop(np.asarray(points), config)


def _crop(p: np.ndarray, config: DetectionConfig):
    """Indices of the points `crop_mask` keeps, and their x and y: by the compiled kernel
    `cloud_crop.c` (one pass over the cloud, through its strides), or `_crop_numpy`."""
    if not _compiled_crop(p):
        return _crop_numpy(p, config)
    n = len(p)
    idx, x, y = np.empty(n, np.int64), np.empty(n, p.dtype), np.empty(n, p.dtype)
    m = _crop_pass(p, config, pointer(idx), pointer(x), pointer(y), None)
    return idx[:m], x[:m], y[:m]


def crop_rows(points, config: DetectionConfig = DEFAULT) -> np.ndarray:
    """The points of a clean (N, 3) cloud that `crop_mask` keeps, as an (M, 3) array of
    the cloud's dtype in the cloud's order (`points[crop_xy(points)[0]]`, gathered in one
    compiled pass)."""
    p = np.asarray(points)
    if not _compiled_crop(p):
        return p[_crop_numpy(p, config)[0]]
    out = np.empty((len(p), 3), p.dtype)
    return out[:_crop_pass(p, config, None, None, None, pointer(out))]


def _compiled_crop(p: np.ndarray) -> bool:
    """The compiled crop takes this cloud: a non-empty (N, 3) float cloud, and a kernel."""
    return (p.dtype in (np.float32, np.float64) and p.ndim == 2 and p.shape[1] == 3
            and len(p) > 0 and crop_kernel() is not None)


def _crop_pass(p: np.ndarray, config: DetectionConfig, idx, x, y, rows) -> int:
    """One pass of `cloud_crop.c` over `p` (outputs by address, None: not wanted): how many
    points the crop keeps."""
    lib = crop_kernel()
    crop = lib.crop_f32 if p.dtype == np.float32 else lib.crop_f64
    size = p.itemsize
    x0, x1 = config.hull_x_m
    return crop(len(p), p.__array_interface__["data"][0], p.strides[0] // size,
                p.strides[1] // size, config.min_height_m, config.max_height_m,
                config.range_m, x0, x1, config.hull_half_width_m, x0 - config.wake_length_m,
                config.wake_half_width_m, idx, x, y, rows)


def _crop_numpy(p: np.ndarray, config: DetectionConfig):
    """`_crop`'s numpy twin. The height band (a few percent of a scan: the wall faces) is
    tested first on the whole cloud, the rest on what it keeps; columns are gathered one by
    one (fast for C- and Fortran-ordered clouds)."""
    z = p[:, 2]
    idx = np.flatnonzero((z <= -config.min_height_m) & (z >= -config.max_height_m))  # z down
    x, y = p[:, 0].take(idx), p[:, 1].take(idx)
    ay = np.abs(y)
    x0, x1 = config.hull_x_m
    r = config.range_m
    keep = (x >= -r) & (x <= r) & (ay <= r)
    keep &= ~((x >= x0) & (x <= x1) & (ay <= config.hull_half_width_m))
    keep &= ~((x >= x0 - config.wake_length_m) & (x < x0) & (ay <= config.wake_half_width_m))
    keep = np.flatnonzero(keep)
    return idx[keep], x[keep], y[keep]


def _cropped_xy(cloud: np.ndarray, config: DetectionConfig) -> np.ndarray:
    """(N, 2) float64 x, y of the points the crop keeps."""
    _, x, y = _crop(cloud, config)
    xy = np.empty((len(x), 2))
    xy[:, 0], xy[:, 1] = x, y
    return xy


# -- input checks -----------------------------------------------------------------------
def _checked_cloud(points) -> np.ndarray:
    arr = np.asarray(points)
    if arr.dtype.kind not in "fiu":
        raise InputError(f"detection: points must be a numeric (N, 3) array of x, y, z in "
                         f"metres, got dtype {arr.dtype}")
    if arr.size == 0:
        return np.zeros((0, 3))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"detection: points must have shape (N, 3) (x, y, z in the body "
                         f"frame), got {arr.shape}")
    if arr.dtype.kind != "f":
        arr = arr.astype(float)
    if np.isfinite(arr.sum()):  # NaN or inf anywhere spoils the sum (one cheap pass)
        return arr
    finite = np.isfinite(arr).all(axis=1)
    bad = int(len(arr) - np.count_nonzero(finite))
    if bad:
        warnings.warn(f"detection: dropped {bad} of {len(arr)} points with NaN or inf "
                      "coordinates", RuntimeWarning, stacklevel=3)
        arr = arr[finite]
    return arr


def _checked_pose(pose) -> tuple[float, float, float]:
    try:
        p = np.asarray(pose, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"detection: pose must be (x, y, psi) numbers, got {pose!r}") from None
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise InputError(f"detection: pose must be three finite numbers (x, y, psi), got {pose!r}")
    return float(p[0]), float(p[1]), float(p[2])


# -- the pipeline (body frame, 2-D) -------------------------------------------------------
def _half_turn(theta):
    """Direction of an undirected line in [-pi/2, pi/2)."""
    return (np.asarray(theta) + np.pi / 2) % np.pi - np.pi / 2


def _fit_segments(xy: np.ndarray, cfg: DetectionConfig) -> np.ndarray:
    """(M, 4) body-frame segments from cropped (N, 2) points."""
    if len(xy) < cfg.min_points:
        return np.zeros((0, 4))
    grid, cells = _occupancy(xy, cfg)
    pieces = _hough_pieces(grid, cfg)
    if not len(pieces):
        return np.zeros((0, 4))
    xy = cells  # one point per occupied cell (their centroid) from here on
    chords = _refit(_merge(pieces, cfg), xy, cfg)
    if not chords:
        return np.zeros((0, 4))
    ends = np.array(chords, float).reshape(-1, 2, 2)
    a, b = _join_corners(ends[:, 0], ends[:, 1], cfg)
    segments = _as_centre_form(a, b)
    # A short chord whose two ends were both moved to one corner would be a point:
    # segments shorter than the minimum are dropped here as the pieces were.
    return segments[segments[:, 3] >= cfg.min_length_m]


def _join_corners(a: np.ndarray, b: np.ndarray, cfg: DetectionConfig):
    """Move the ends of two segments that meet at an angle (a corner, a pier on a wall) to
    where their lines cross, if that point is within `corner_join_m` of both ends: each
    face then reaches the corner instead of stopping where the other face took its points.
    """
    ends = np.concatenate([a, b])  # end k belongs to segment k % M
    m = len(a)
    seg = np.arange(2 * m) % m
    d = b - a
    u = d / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
    close = np.hypot(*(ends[:, None, :] - ends[None, :, :]).transpose(2, 0, 1)) <= cfg.corner_join_m
    sin = np.abs(u[seg][:, None, 0] * u[seg][None, :, 1] - u[seg][:, None, 1] * u[seg][None, :, 0])
    pairs = np.argwhere(close & (sin >= math.sin(math.radians(20.0)))
                        & (seg[:, None] < seg[None, :]))
    if not len(pairs):
        return a, b
    moved = ends.copy()
    for i, j in pairs.tolist():
        px, py = ends[i].tolist()
        rx, ry = u[seg[i]].tolist()
        qx, qy = ends[j].tolist()
        sx, sy = u[seg[j]].tolist()
        denom = rx * sy - ry * sx
        t = ((qx - px) * sy - (qy - py) * sx) / denom
        x, y = px + t * rx, py + t * ry
        if (math.hypot(x - px, y - py) <= cfg.corner_join_m
                and math.hypot(x - qx, y - qy) <= cfg.corner_join_m):
            moved[i] = moved[j] = (x, y)
    return moved[:m], moved[m:]


def _chords(pts: np.ndarray, cfg: DetectionConfig, line=None, t=None):
    """Split the points of one fitted line into chords where the wall bends.

    The points, ordered along the line and averaged in bins two cells long (which tames the
    range noise), form a path; Douglas-Peucker splits that path wherever it strays more than
    `chord_tolerance_m` from the chord between its ends, so a corner is split at the corner
    and a bend of radius R becomes chords within sqrt(2 tol / R) rad of it. Each piece is
    then fitted to its own points (total least squares). Chords are ((x, y), (x, y)) pairs.
    `line` (centre and direction) and `t` (positions along it, ascending, points in that
    order): the fit of exactly these points if the caller has it.
    """
    if line is None:
        line = _principal(pts)
        cx, cy, wx, wy = line
        t = pts @ np.array((wx, wy))
        t -= cx * wx + cy * wy
        order = np.argsort(t)
        pts, t = pts[order], t[order]
    cx, cy, wx, wy = line
    t0, t1 = float(t[0]), float(t[-1])
    if t1 - t0 < 2 * cfg.min_length_m:
        return [((cx + t0 * wx, cy + t0 * wy), (cx + t1 * wx, cy + t1 * wy))]
    bins = ((t - t0) * (0.5 / cfg.cell_m)).astype(np.intp)  # t - t0 >= 0: truncation floors
    change = np.flatnonzero(bins[1:] != bins[:-1])
    change += 1
    starts = np.concatenate(([0], change))
    counts = np.concatenate((change, [len(t)]))
    counts -= starts
    path = np.add.reduceat(pts, starts, axis=0) / counts[:, None]
    path_t = np.add.reduceat(t, starts) / counts
    cuts = sorted(_douglas_peucker(path, path.tolist(), path_t.tolist(), 0, len(path) - 1, cfg))
    if not cuts:
        pieces = [(pts, line)]
    else:
        edges = np.concatenate(([t0 - 1.0], path_t[cuts], [t1 + 1.0]))
        first = np.searchsorted(t, edges[:-1], "left")
        last = np.searchsorted(t, edges[1:], "right")
        pieces = [(pts[i:j], None) for i, j in zip(first.tolist(), last.tolist())]
    out = []
    for sub, fit in pieces:
        if len(sub) < 2:
            continue
        cx, cy, vx, vy = fit or _principal(sub)
        # Refit without the points off the chord (a perpendicular face at a corner).
        off = sub @ np.array((-vy, vx))
        off -= cy * vx - cx * vy
        close = np.abs(off) <= cfg.fit_band_m
        n_close = int(np.count_nonzero(close))
        if n_close >= max(2, cfg.min_points) and n_close < len(close):
            cx, cy, vx, vy = _principal(sub[close])
        s = sub @ np.array((vx, vy))
        s0 = float(s.min()) - (cx * vx + cy * vy)
        s1 = float(s.max()) - (cx * vx + cy * vy)
        out.append(((cx + s0 * vx, cy + s0 * vy), (cx + s1 * vx, cy + s1 * vy)))
    return out


def _douglas_peucker(path, coords, path_t, i, j, cfg) -> list[int]:
    """Indices of `path` strictly between i and j where it must be split (see _chords);
    `coords` and `path_t` are `path` and its positions along the line as Python lists."""
    if j - i < 2:
        return []
    ax, ay = coords[i]
    bx, by = coords[j]
    dx, dy = bx - ax, by - ay
    length = math.hypot(dx, dy)
    if length <= 0:
        return []
    off = path[i + 1:j] @ np.array((-dy, dx))
    off -= ay * dx - ax * dy
    np.abs(off, out=off)
    k = int(np.argmax(off))
    if off[k] / length <= cfg.chord_tolerance_m:
        return []
    k += i + 1
    if path_t[k] - path_t[i] < cfg.min_length_m or path_t[j] - path_t[k] < cfg.min_length_m:
        return []
    return (_douglas_peucker(path, coords, path_t, i, k, cfg) + [k]
            + _douglas_peucker(path, coords, path_t, k, j, cfg))


def _principal(pts: np.ndarray) -> tuple[float, float, float, float]:
    """Centre (x, y) and unit direction (x, y) of the total-least-squares line through the
    points (the major axis of their 2x2 covariance, in closed form), as floats."""
    n = len(pts)
    if n > len(_ONES):
        sx, sy = float(pts[:, 0].sum()), float(pts[:, 1].sum())
    else:  # (column sums as one product with ones: one call, not two)
        sx, sy = (_ONES[:n] @ pts).tolist()
    mxx, mxy, _, myy = (pts.T @ pts).ravel().tolist()
    cx, cy = sx / n, sy / n
    angle = 0.5 * math.atan2(2.0 * (mxy / n - cx * cy), (mxx / n - cx * cx) - (myy / n - cy * cy))
    return cx, cy, math.cos(angle), math.sin(angle)


_ONES = np.ones(4096)


def _occupancy(xy: np.ndarray, cfg: DetectionConfig):
    """The occupancy grid (rows along x, columns along y, 255 = occupied) and the centroid of
    the points in each occupied cell: the grid is what Hough sees, the centroids what the
    lines are fitted to (as exact as the points, a fraction of their number). By the
    compiled kernel `occupancy.c` (the same sums in the same order), or `_occupancy_numpy`."""
    lib = occupancy_kernel()
    if lib is None:
        return _occupancy_numpy(xy, cfg)
    n = int(math.ceil(2 * cfg.range_m / cfg.cell_m))
    x, y = np.ascontiguousarray(xy[:, 0], float), np.ascontiguousarray(xy[:, 1], float)
    m = len(x)
    grid = np.empty((n, n), np.uint8)
    flat = np.empty(m, np.int64)
    scratch = _scratch(n * n)
    sums = np.empty((3, m))
    k = lib.occupancy(m, pointer(x), pointer(y), n, float(cfg.range_m), 1.0 / cfg.cell_m,
                      pointer(grid), pointer(flat), pointer(scratch), pointer(sums[0]),
                      pointer(sums[1]), pointer(sums[2]))
    centroids = np.empty((k, 2))
    centroids[:, 0], centroids[:, 1] = sums[0, :k], sums[1, :k]
    return grid, centroids


_SCRATCH: list = []


def _scratch(size: int) -> np.ndarray:
    """A reused int64 buffer of at least `size` (the kernel's cell lookup; not zeroed)."""
    if not _SCRATCH or len(_SCRATCH[0]) < size:
        _SCRATCH[:] = [np.empty(size, np.int64)]
    return _SCRATCH[0]


def _occupancy_numpy(xy: np.ndarray, cfg: DetectionConfig):
    """`_occupancy`'s numpy twin."""
    n = int(math.ceil(2 * cfg.range_m / cfg.cell_m))
    # (Column by column: reductions along the short axis of an (N, 2) array are slow.)
    x, y = xy[:, 0], xy[:, 1]
    i = np.floor((x + cfg.range_m) * (1.0 / cfg.cell_m)).astype(np.intp)
    j = np.floor((y + cfg.range_m) * (1.0 / cfg.cell_m)).astype(np.intp)
    inside = (i >= 0) & (i < n) & (j >= 0) & (j < n)
    if not inside.all():
        i, j, x, y = i[inside], j[inside], x[inside], y[inside]
    flat = i * n + j
    grid = np.zeros(n * n, np.uint8)
    grid[flat] = 255
    cells = np.flatnonzero(grid.view(bool))  # sorted; (a bool view counts much faster)
    lookup = np.empty(n * n, np.intp)  # cell -> its index in `cells`; only those entries set
    lookup[cells] = np.arange(len(cells))
    which = lookup[flat]
    count = np.bincount(which, minlength=len(cells))
    centroids = np.column_stack([np.bincount(which, x, len(cells)) / count,
                                 np.bincount(which, y, len(cells)) / count])
    return grid.reshape(n, n), centroids


def _hough_pieces(grid: np.ndarray, cfg: DetectionConfig) -> list:
    """Probabilistic Hough pieces of the occupancy grid, as body-frame endpoint pairs
    ((x, y), (x, y))."""
    found = opencv.cv2().HoughLinesP(
        grid, 1.0, math.radians(cfg.hough_theta_deg), cfg.hough_votes,
        minLineLength=cfg.min_length_m / cfg.cell_m, maxLineGap=_max_gap(cfg, cfg.range_m) / cfg.cell_m)
    if found is None:
        return []
    px = found.reshape(-1, 4).astype(float)
    # OpenCV returns (column, row) pairs: column is y, row is x; cell centres in metres.
    ends = (px[:, [1, 0, 3, 2]] + 0.5) * cfg.cell_m - cfg.range_m
    return [((ax, ay), (bx, by)) for ax, ay, bx, by in ends.tolist()]


def _merge(pieces, cfg: DetectionConfig):
    """Greedy clustering, longest first: a piece joins a line when it is parallel within
    `merge_angle_deg`, both ends lie within `merge_offset_m` of the line, and it overlaps
    the line or leaves a gap shorter than `max_gap_m`. Returns (a, b) endpoint pairs.
    (A few dozen pieces: plain floats, no arrays.)"""
    hypot = math.hypot
    order = sorted(pieces, key=lambda ab: -hypot(ab[1][0] - ab[0][0], ab[1][1] - ab[0][1]))
    sin_tol = math.sin(math.radians(cfg.merge_angle_deg))
    offset = cfg.merge_offset_m
    lines = []  # [origin x, y, unit direction x, y, s_min, s_max]
    for (ax, ay), (bx, by) in order:
        length = hypot(bx - ax, by - ay)
        if length <= 0:
            continue
        ux, uy = (bx - ax) / length, (by - ay) / length
        for line in lines:
            ox, oy, vx, vy, s0, s1 = line
            if abs(ux * vy - uy * vx) > sin_tol:
                continue
            if (abs(vx * (ay - oy) - vy * (ax - ox)) > offset
                    or abs(vx * (by - oy) - vy * (bx - ox)) > offset):
                continue
            sa, sb = sorted((vx * (ax - ox) + vy * (ay - oy), vx * (bx - ox) + vy * (by - oy)))
            gap = cfg.max_gap_m + cfg.gap_per_range * min(
                hypot(ax, ay), hypot(bx, by), hypot(ox + s0 * vx, oy + s0 * vy),
                hypot(ox + s1 * vx, oy + s1 * vy))
            if sa > s1 + gap or sb < s0 - gap:
                continue
            line[4], line[5] = min(s0, sa), max(s1, sb)
            break
        else:
            lines.append([ax, ay, ux, uy, 0.0, length])
    return [((ox + s0 * vx, oy + s0 * vy), (ox + s1 * vx, oy + s1 * vy))
            for ox, oy, vx, vy, s0, s1 in lines]


def _refit(lines, xy: np.ndarray, cfg: DetectionConfig):
    """`_refit_numpy` by the compiled kernel `wall_fit.c` (the same steps, equal to rounding),
    or by numpy where no kernel can be built."""
    lib = wall_fit_kernel()
    if lib is None:
        return _refit_numpy(lines, xy, cfg)
    hypot = math.hypot
    order = sorted(lines, key=lambda ab: -hypot(ab[1][0] - ab[0][0], ab[1][1] - ab[0][1]))
    order = [ab for ab in order if hypot(ab[1][0] - ab[0][0], ab[1][1] - ab[0][1]) > 0]
    return refit_compiled(lib, order, xy, cfg) if order else []


def _refit_numpy(lines, xy: np.ndarray, cfg: DetectionConfig):
    """Fit each line to the points near it (total least squares), longest line first, each
    point used once; split where the points leave a gap longer than the allowed gap there,
    and each run into chords (`_chords`). Returns the chords as (a, b) endpoint pairs.

    A few hundred cells and a dozen lines: the per-line work is a handful of array
    operations, with the line itself in plain floats."""
    free = np.ones(len(xy), bool)
    out = []
    reach = float(_max_gap(cfg, cfg.range_m))
    hypot = math.hypot
    order = sorted(lines, key=lambda ab: -hypot(ab[1][0] - ab[0][0], ab[1][1] - ab[0][1]))
    order = [ab for ab in order if hypot(ab[1][0] - ab[0][0], ab[1][1] - ab[0][1]) > 0]
    first = _bands(order, xy, reach, cfg.inlier_m)  # the first selection of every line
    for k, ((ax, ay), (bx, by)) in enumerate(order):
        length = hypot(bx - ax, by - ay)
        ox, oy, vx, vy = ax, ay, (bx - ax) / length, (by - ay) / length
        sel = None
        for it in range(2):  # select, fit, select again around the fitted line
            # Along-line and perpendicular coordinates of every cell, relative to the middle
            # of the line: |along| <= length / 2 + reach and |perp| <= inlier_m selects.
            half = 0.5 * length
            if it == 0:
                sel = np.flatnonzero(first[k] & free)
            else:
                perp = xy @ np.array((-vy, vx))
                perp -= oy * vx - ox * vy
                near = np.abs(perp, out=perp) <= cfg.inlier_m
                near &= free
                sel = np.flatnonzero(near)
                along = xy[sel] @ np.array((vx, vy))
                along -= ox * vx + oy * vy + half
                sel = sel[np.abs(along, out=along) <= half + reach]
            if len(sel) < cfg.min_points:
                sel = None
                break
            pts = xy[sel]
            cx, cy, wx, wy = _principal(pts)
            flipped = wx * vx + wy * vy < 0
            if flipped:
                wx, wy = -wx, -wy
            s = pts @ np.array((wx, wy))
            s0 = float(s.min())
            length = float(s.max()) - s0
            s -= s0  # along the fitted line, from its first point
            s0 -= cx * wx + cy * wy
            ox, oy, vx, vy = cx + s0 * wx, cy + s0 * wy, wx, wy
        if sel is None:
            continue
        order_s = np.argsort(s)
        s, sel = s[order_s], sel[order_s]
        gaps = np.diff(s)
        wide = np.flatnonzero(gaps > cfg.max_gap_m)  # the allowed gap is never smaller
        if len(wide):
            mid = 0.5 * (s[wide + 1] + s[wide])  # the middle of each gap
            allowed = _max_gap(cfg, np.hypot(ox + mid * vx, oy + mid * vy))
            wide = wide[gaps[wide] > allowed]
        bounds = [0] + (wide + 1).tolist() + [len(s)]
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            if hi - lo < cfg.min_points or s[hi - 1] - s[lo] < cfg.min_length_m:
                continue
            run = sel[lo:hi]
            run_xy = xy[run]
            if hi - lo == len(s):  # one run of all the points: the fit above is theirs
                if flipped:  # (as _principal gave it: the chord path starts at that end)
                    chords = _chords(run_xy[::-1], cfg, (cx, cy, -vx, -vy), -(s + s0)[::-1])
                else:
                    chords = _chords(run_xy, cfg, (cx, cy, vx, vy), s + s0)
            else:
                chords = _chords(run_xy, cfg)
            if not chords:
                continue
            # Claim only the points on the chords: those of a perpendicular face that the
            # band reached at a corner stay free for that face's own line.
            out.extend(chords)
            free[run[_near_chords(run_xy, chords, cfg.fit_band_m)]] = False
    return out


def _bands(lines, xy: np.ndarray, reach: float, inlier: float) -> np.ndarray:
    """(L, N) mask: cell n lies within `inlier` of line l and along it no farther than
    `reach` beyond its ends (all lines in one matrix product)."""
    ends = np.array(lines, float).reshape(-1, 4)
    d = ends[:, 2:] - ends[:, :2]
    half = 0.5 * np.hypot(d[:, 0], d[:, 1])
    v = d / (2 * half)[:, None]
    # Columns 2l and 2l + 1: along line l (from its middle) and across it.
    r = np.empty((2, 2 * len(ends)))
    r[:, 0::2], r[0, 1::2], r[1, 1::2] = v.T, -v[:, 1], v[:, 0]
    centre = ends[:, :2] + v * half[:, None]
    offset = np.empty(2 * len(ends))
    offset[0::2] = centre[:, 0] * v[:, 0] + centre[:, 1] * v[:, 1]
    offset[1::2] = ends[:, 1] * v[:, 0] - ends[:, 0] * v[:, 1]
    limit = np.empty(2 * len(ends))
    limit[0::2], limit[1::2] = half + reach, inlier
    sp = xy @ r
    sp -= offset
    ok = np.abs(sp, out=sp) <= limit
    return np.ascontiguousarray((ok[:, 0::2] & ok[:, 1::2]).T)


def _near_chords(pts: np.ndarray, chords, band: float) -> np.ndarray:
    """Which points lie within `band` of one of the chords ((x, y), (x, y)); all chords at
    once, as an (N, C) table of each point's nearest position on each chord."""
    c = np.array(chords, float).reshape(-1, 4)
    ax, ay = c[:, 0], c[:, 1]
    dx, dy = c[:, 2] - ax, c[:, 3] - ay
    d2 = dx * dx + dy * dy
    safe = np.where(d2 > 0, d2, 1.0)  # a chord of no length: t = 0, its one point
    rx = pts[:, 0:1] - ax  # (N, C)
    ry = pts[:, 1:2] - ay
    t = rx * (dx / safe) + ry * (dy / safe)
    np.clip(t, 0.0, 1.0, out=t)
    rx -= t * dx
    ry -= t * dy
    rx *= rx
    ry *= ry
    rx += ry
    return (rx <= band * band).any(axis=1)


def _max_gap(cfg: DetectionConfig, range_m):
    """Largest gap between returns bridged along one line at this range from the boat."""
    return cfg.max_gap_m + cfg.gap_per_range * np.asarray(range_m)


def _as_centre_form(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(M, 4) segments (x_c, y_c, theta, length) from endpoint arrays a, b (M, 2)."""
    d = b - a
    return np.column_stack([0.5 * (a + b), _half_turn(np.arctan2(d[:, 1], d[:, 0])),
                            np.hypot(d[:, 0], d[:, 1])])
