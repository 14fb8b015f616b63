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
from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .geometry import point_segment_distance


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
    body = _fit_segments(cloud[crop_mask(cloud, config), :2].astype(float), config)
    if not len(body):
        return np.zeros((0, 4))
    c, s = math.cos(psi), math.sin(psi)
    xc = x + c * body[:, 0] - s * body[:, 1]
    yc = y + s * body[:, 0] + c * body[:, 1]
    theta = _half_turn(body[:, 2] + psi)
    out = np.column_stack([xc, yc, theta, body[:, 3]])
    return out[np.argsort(-out[:, 3], kind="stable")]


def crop_mask(points, config: DetectionConfig = DEFAULT) -> np.ndarray:
    """Which points of a clean (N, 3) body-frame cloud the detector keeps (paper Fig. (c))."""
    p = np.asarray(points)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    keep = (z <= -config.min_height_m) & (z >= -config.max_height_m)  # z is down
    ay = np.abs(y)
    keep &= (np.abs(x) <= config.range_m) & (ay <= config.range_m)
    x0, x1 = config.hull_x_m
    keep &= ~((x >= x0) & (x <= x1) & (ay <= config.hull_half_width_m))
    keep &= ~((x >= x0 - config.wake_length_m) & (x < x0) & (ay <= config.wake_half_width_m))
    return keep


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
    finite = np.isfinite(arr[:, 0] + arr[:, 1] + arr[:, 2])  # NaN or inf spoils the sum
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
    a, b = _join_corners(np.array([c[0] for c in chords]), np.array([c[1] for c in chords]), cfg)
    return np.array([_as_centre_form(p, q) for p, q in zip(a, b)]).reshape(-1, 4)


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
    moved = ends.copy()
    for i, j in pairs:
        p, r = ends[i], u[seg[i]]
        q, s = ends[j], u[seg[j]]
        denom = r[0] * s[1] - r[1] * s[0]
        t = ((q[0] - p[0]) * s[1] - (q[1] - p[1]) * s[0]) / denom
        x = p + t * r
        if np.hypot(*(x - p)) <= cfg.corner_join_m and np.hypot(*(x - q)) <= cfg.corner_join_m:
            moved[i], moved[j] = x, x
    return moved[:m], moved[m:]


def _chords(pts: np.ndarray, cfg: DetectionConfig):
    """Split the points of one fitted line into chords where the wall bends.

    The points, ordered along the line and averaged in bins two cells long (which tames the
    range noise), form a path; Douglas-Peucker splits that path wherever it strays more than
    `chord_tolerance_m` from the chord between its ends, so a corner is split at the corner
    and a bend of radius R becomes chords within sqrt(2 tol / R) rad of it. Each piece is
    then fitted to its own points (total least squares).
    """
    centre, w = _principal(pts)
    t = (pts - centre) @ w
    order = np.argsort(t)
    pts, t = pts[order], t[order]
    if t[-1] - t[0] < 2 * cfg.min_length_m:
        return [(centre + t[0] * w, centre + t[-1] * w)]
    bins = np.floor((t - t[0]) / (2 * cfg.cell_m)).astype(int)
    starts = np.flatnonzero(np.r_[True, np.diff(bins) > 0])
    counts = np.diff(np.r_[starts, len(t)])
    path = np.add.reduceat(pts, starts, axis=0) / counts[:, None]
    path_t = np.add.reduceat(t, starts) / counts
    cuts = sorted(_douglas_peucker(path, path_t, 0, len(path) - 1, cfg))
    edges = [t[0] - 1.0] + [path_t[k] for k in cuts] + [t[-1] + 1.0]
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sub = pts[(t >= lo) & (t <= hi)]
        if len(sub) >= 2:
            c, v = _principal(sub)
            # Refit without the points off the chord (a perpendicular face at a corner).
            close = np.abs((sub - c) @ np.array([-v[1], v[0]])) <= cfg.fit_band_m
            if close.sum() >= max(2, cfg.min_points) and not close.all():
                c, v = _principal(sub[close])
            s = (sub - c) @ v
            out.append((c + s.min() * v, c + s.max() * v))
    return out


def _douglas_peucker(path, path_t, i, j, cfg) -> list[int]:
    """Indices of `path` strictly between i and j where it must be split (see _chords)."""
    if j - i < 2:
        return []
    a, b = path[i], path[j]
    d = b - a
    length = math.hypot(d[0], d[1])
    if length <= 0:
        return []
    off = np.abs((path[i + 1:j] - a) @ np.array([-d[1], d[0]])) / length
    k = i + 1 + int(np.argmax(off))
    if off[k - i - 1] <= cfg.chord_tolerance_m:
        return []
    if path_t[k] - path_t[i] < cfg.min_length_m or path_t[j] - path_t[k] < cfg.min_length_m:
        return []
    return _douglas_peucker(path, path_t, i, k, cfg) + [k] + _douglas_peucker(path, path_t, k, j, cfg)


def _principal(pts: np.ndarray):
    """Centre and unit direction of the total-least-squares line through points (the major
    axis of their 2x2 covariance, in closed form)."""
    n = len(pts)
    centre = pts.sum(axis=0) / n
    m = pts.T @ pts / n - np.outer(centre, centre)
    angle = 0.5 * math.atan2(2.0 * m[0, 1], m[0, 0] - m[1, 1])
    return centre, np.array([math.cos(angle), math.sin(angle)])


def _occupancy(xy: np.ndarray, cfg: DetectionConfig):
    """The occupancy grid (rows along x, columns along y, 255 = occupied) and the centroid of
    the points in each occupied cell: the grid is what Hough sees, the centroids what the
    lines are fitted to (as exact as the points, a fraction of their number)."""
    n = int(math.ceil(2 * cfg.range_m / cfg.cell_m))
    ij = np.floor((xy + cfg.range_m) / cfg.cell_m).astype(np.int64)
    inside = ((ij >= 0) & (ij < n)).all(axis=1)
    ij, xy = ij[inside], xy[inside]
    flat = ij[:, 0] * n + ij[:, 1]
    cells, which, count = np.unique(flat, return_inverse=True, return_counts=True)
    centroids = np.column_stack([np.bincount(which, xy[:, k], len(cells)) / count
                                 for k in range(2)])
    grid = np.zeros(n * n, np.uint8)
    grid[cells] = 255
    return grid.reshape(n, n), centroids


def _hough_pieces(grid: np.ndarray, cfg: DetectionConfig) -> list[tuple[np.ndarray, np.ndarray]]:
    """Probabilistic Hough pieces of the occupancy grid, as body-frame endpoint pairs."""
    import cv2

    found = cv2.HoughLinesP(
        grid, 1.0, math.radians(cfg.hough_theta_deg), cfg.hough_votes,
        minLineLength=cfg.min_length_m / cfg.cell_m, maxLineGap=_max_gap(cfg, cfg.range_m) / cfg.cell_m)
    if found is None:
        return []
    px = found.reshape(-1, 4).astype(float)
    # OpenCV returns (column, row) pairs: column is y, row is x; cell centres in metres.
    a = (px[:, [1, 0]] + 0.5) * cfg.cell_m - cfg.range_m
    b = (px[:, [3, 2]] + 0.5) * cfg.cell_m - cfg.range_m
    return list(zip(a, b))


def _merge(pieces, cfg: DetectionConfig):
    """Greedy clustering, longest first: a piece joins a line when it is parallel within
    `merge_angle_deg`, both ends lie within `merge_offset_m` of the line, and it overlaps
    the line or leaves a gap shorter than `max_gap_m`. Returns (a, b) endpoint pairs."""
    order = sorted(pieces, key=lambda ab: -np.hypot(*(ab[1] - ab[0])))
    tol = math.radians(cfg.merge_angle_deg)
    lines = []  # [origin, unit direction, s_min, s_max]
    for a, b in order:
        d = b - a
        length = math.hypot(d[0], d[1])
        if length <= 0:
            continue
        u = d / length
        for line in lines:
            o, v, s0, s1 = line
            if abs(u[0] * v[1] - u[1] * v[0]) > math.sin(tol):
                continue
            n = np.array([-v[1], v[0]])
            if abs(n @ (a - o)) > cfg.merge_offset_m or abs(n @ (b - o)) > cfg.merge_offset_m:
                continue
            sa, sb = sorted((v @ (a - o), v @ (b - o)))
            gap = _max_gap(cfg, min(np.hypot(*a), np.hypot(*b), np.hypot(*(o + s0 * v)),
                                    np.hypot(*(o + s1 * v))))
            if sa > s1 + gap or sb < s0 - gap:
                continue
            line[2], line[3] = min(s0, sa), max(s1, sb)
            break
        else:
            lines.append([a.copy(), u, 0.0, length])
    return [(o + s0 * v, o + s1 * v) for o, v, s0, s1 in lines]


def _refit(lines, xy: np.ndarray, cfg: DetectionConfig):
    """Fit each line to the points near it (total least squares), longest line first, each
    point used once; split where the points leave a gap longer than the allowed gap there,
    and each run into chords (`_chords`). Returns the chords as (a, b) endpoint pairs."""
    free = np.ones(len(xy), bool)
    out = []
    for a, b in sorted(lines, key=lambda ab: -np.hypot(*(ab[1] - ab[0]))):
        d = b - a
        length = math.hypot(d[0], d[1])
        if length <= 0:
            continue
        o, v = a, d / length
        sel = None
        for _ in range(2):  # select, fit, select again around the fitted line
            n = np.array([-v[1], v[0]])
            rel = xy - o
            s = rel @ v
            near = free & (np.abs(rel @ n) <= cfg.inlier_m)
            reach = _max_gap(cfg, cfg.range_m)
            near &= (s >= -reach) & (s <= length + reach)
            if near.sum() < cfg.min_points:
                sel = None
                break
            sel = np.flatnonzero(near)
            pts = xy[sel]
            centre, w = _principal(pts)
            w = w if w @ v >= 0 else -w
            s_pts = (pts - centre) @ w
            o, v = centre + s_pts.min() * w, w
            length = float(s_pts.max() - s_pts.min())
        if sel is None:
            continue
        s = (xy[sel] - o) @ v
        order = np.argsort(s)
        s, sel = s[order], sel[order]
        mid = o + 0.5 * (s[1:] + s[:-1])[:, None] * v  # the middle of each gap
        breaks = np.flatnonzero(np.diff(s) > _max_gap(cfg, np.hypot(mid[:, 0], mid[:, 1]))) + 1
        for run_s, run in zip(np.split(s, breaks), np.split(sel, breaks)):
            if len(run) < cfg.min_points or run_s[-1] - run_s[0] < cfg.min_length_m:
                continue
            chords = _chords(xy[run], cfg)
            if not chords:
                continue
            # Claim only the points on the chords: those of a perpendicular face that the
            # band reached at a corner stay free for that face's own line.
            ca = np.array([c[0] for c in chords])
            cb = np.array([c[1] for c in chords])
            on = point_segment_distance(xy[run], ca, cb).min(axis=1) <= cfg.fit_band_m
            out.extend(chords)
            free[run[on]] = False
    return out


def _max_gap(cfg: DetectionConfig, range_m):
    """Largest gap between returns bridged along one line at this range from the boat."""
    return cfg.max_gap_m + cfg.gap_per_range * np.asarray(range_m)


def _as_centre_form(a, b) -> np.ndarray:
    d = b - a
    return np.array([(a[0] + b[0]) / 2, (a[1] + b[1]) / 2,
                     float(_half_turn(math.atan2(d[1], d[0]))), math.hypot(d[0], d[1])])
