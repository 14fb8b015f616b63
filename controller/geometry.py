"""Plane geometry shared by detection, reference, metrics and the LiDAR simulator.

Conventions: points are (x north, y east) in metres; angles are measured from north (x),
clockwise positive toward east (y), like the heading psi. All functions are pure and
vectorised over numpy arrays.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from .kernels import Kernel, pointer

_nearest_leg_kernel = Kernel(Path(__file__).with_name("kernels") / "nearest_leg.c", {
    "nearest_leg": (None, [ctypes.c_int64, ctypes.c_void_p, ctypes.c_int64, ctypes.c_void_p,
                           ctypes.c_void_p, ctypes.c_void_p])})


def wrap_angle(angle):
    """Wrap to [-pi, pi) (Fossen's `ssa`)."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


def unwrap_near(angle, reference):
    """The angle equal to `angle` modulo 2 pi that lies closest to `reference`."""
    return reference + wrap_angle(np.asarray(angle) - reference)


@dataclass(frozen=True)
class Segment:
    """A line segment L = (x_c, y_c, theta, length) as in the paper's eq. line."""

    x_c: float
    y_c: float
    theta: float  # rad, direction of the segment, from north clockwise
    length: float  # m

    @property
    def endpoints(self) -> tuple[np.ndarray, np.ndarray]:
        d = 0.5 * self.length * np.array([np.cos(self.theta), np.sin(self.theta)])
        c = np.array([self.x_c, self.y_c])
        return c - d, c + d

    @classmethod
    def from_endpoints(cls, a, b) -> "Segment":
        a, b = np.asarray(a, float), np.asarray(b, float)
        d = b - a
        return cls(
            float((a[0] + b[0]) / 2), float((a[1] + b[1]) / 2),
            float(np.arctan2(d[1], d[0])), float(np.hypot(d[0], d[1])),
        )

    def as_array(self) -> np.ndarray:
        return np.array([self.x_c, self.y_c, self.theta, self.length])


def segments_to_endpoints(segments) -> tuple[np.ndarray, np.ndarray]:
    """(M, 4) array of (x_c, y_c, theta, length) -> two (M, 2) arrays of endpoints."""
    s = np.asarray(segments, float).reshape(-1, 4)
    half = 0.5 * s[:, 3:4] * np.column_stack([np.cos(s[:, 2]), np.sin(s[:, 2])])
    return s[:, :2] - half, s[:, :2] + half


def point_segment_distance(points, a, b) -> np.ndarray:
    """Distance from each of N points to each of M segments a-b: an (N, M) array."""
    p = np.asarray(points, float).reshape(-1, 2)[:, None, :]
    a = np.asarray(a, float).reshape(-1, 2)[None, :, :]
    b = np.asarray(b, float).reshape(-1, 2)[None, :, :]
    ab = b - a
    denom = np.einsum("ijk,ijk->ij", ab, ab)
    t = np.einsum("ijk,ijk->ij", p - a, ab) / np.where(denom > 0, denom, 1.0)
    t = np.clip(t, 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.linalg.norm(p - closest, axis=-1)


def nearest_leg_distance(points, a, b) -> np.ndarray:
    """Distance (N,) from each point to the nearest of the segments a-b (inf: none):
    `point_segment_distance(points, a, b).min(axis=1)`, by the kernel `nearest_leg.c` (the
    same arithmetic) or, where none can be built, that numpy expression."""
    p = np.ascontiguousarray(points, float).reshape(-1, 2)
    a = np.ascontiguousarray(a, float).reshape(-1, 2)
    b = np.ascontiguousarray(b, float).reshape(-1, 2)
    if not len(a):
        return np.full(len(p), np.inf)
    lib = _nearest_leg_kernel()
    if lib is None:
        return point_segment_distance(p, a, b).min(axis=1)
    out = np.empty(len(p))
    lib.nearest_leg(len(p), pointer(p), len(a), pointer(a), pointer(b), pointer(out))
    return out


def nearest_leg_compiled() -> bool:
    """`nearest_leg_distance` runs compiled (else its numpy form: pruning the legs first
    pays, as `scenarios.results.metrics.Clearance` does)."""
    return _nearest_leg_kernel() is not None


def polyline_segments(polyline) -> tuple[np.ndarray, np.ndarray]:
    """The consecutive segments of an (K, 2) polyline as endpoint arrays a, b of shape (K-1, 2)."""
    pts = np.asarray(polyline, float).reshape(-1, 2)
    return pts[:-1], pts[1:]


def polyline_legs(polylines) -> tuple[np.ndarray, np.ndarray]:
    """All legs of several (K, 2) polylines as two (M, 2) endpoint arrays a, b (polylines of
    fewer than two points have none)."""
    parts = [np.asarray(p, float).reshape(-1, 2) for p in polylines]
    parts = [p for p in parts if len(p) >= 2]
    if not parts:
        return np.zeros((0, 2)), np.zeros((0, 2))
    return np.vstack([p[:-1] for p in parts]), np.vstack([p[1:] for p in parts])


def distance_to_polylines(points, polylines) -> np.ndarray:
    """Smallest distance from each point to any of the polylines: shape (N,)."""
    points = np.asarray(points, float).reshape(-1, 2)
    best = np.full(len(points), np.inf)
    for line in polylines:
        a, b = polyline_segments(line)
        if len(a):
            best = np.minimum(best, nearest_leg_distance(points, a, b))
    return best


@dataclass(frozen=True)
class Polyline:
    """A path through waypoints with arc-length bookkeeping (for references and cross-track)."""

    points: np.ndarray  # (K, 2)

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, float).reshape(-1, 2)
        object.__setattr__(self, "points", pts)

    @cached_property
    def seg_lengths(self) -> np.ndarray:
        return np.hypot(*np.diff(self.points, axis=0).T)

    @cached_property
    def cumulative(self) -> np.ndarray:
        """Arc length at each vertex, starting at 0."""
        return np.concatenate([[0.0], np.cumsum(self.seg_lengths)])

    @cached_property
    def length(self) -> float:
        return float(self.seg_lengths.sum())

    @cached_property
    def headings(self) -> np.ndarray:
        """Direction of each leg (rad, from north clockwise)."""
        d = np.diff(self.points, axis=0)
        return np.arctan2(d[:, 1], d[:, 0])

    def project(self, point, s_min: float = 0.0, s_max: float | None = None):
        """Closest point on the polyline with arc length in [s_min, s_max].

        Returns (s, closest_xy, distance, leg_index). Searching from a previous progress
        `s_min` keeps a path that doubles back (an S-bend) from jumping backwards.
        """
        p = np.asarray(point, float).reshape(2)
        cum = self.cumulative
        s_max = cum[-1] if s_max is None else min(s_max, cum[-1])
        a, ab, L = self.points[:-1], np.diff(self.points, axis=0), self.seg_lengths
        t = np.einsum("ij,ij->i", p - a, ab) / np.where(L > 0, L * L, 1.0)
        lo, hi = np.maximum(cum[:-1], s_min), np.minimum(cum[1:], s_max)
        s = np.clip(cum[:-1] + np.clip(t, 0.0, 1.0) * L, lo, np.maximum(lo, hi))
        xy = self.at(s)[0]
        d = np.where(lo <= hi, np.hypot(*(xy - p).T), np.inf)
        i = int(np.argmin(d))
        return float(s[i]), xy[i], float(d[i]), i

    def at(self, s):
        """Point(s) and leg heading(s) at arc length(s) s (clamped to the ends)."""
        s = np.atleast_1d(np.asarray(s, float))
        cum = self.cumulative
        s = np.clip(s, 0.0, cum[-1])
        i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(self.points) - 2)
        L = self.seg_lengths[i]
        t = np.where(L > 0, (s - cum[i]) / np.where(L > 0, L, 1.0), 0.0)
        xy = self.points[i] + t[:, None] * (self.points[i + 1] - self.points[i])
        return xy, self.headings[i]

    def cross_track(self, point) -> float:
        """Unsigned distance from a point to the polyline."""
        return float(self.project(point)[2])


def simplify_polyline(points, tolerance_m: float) -> np.ndarray:
    """Ramer-Douglas-Peucker: the fewest vertices that keep the polyline within tolerance_m.

    Long straight walls come back as one segment each, bends as short chords: the shape a
    line detector reports, and what a fixed number of segment slots can hold.
    """
    pts = np.asarray(points, float).reshape(-1, 2)
    if len(pts) <= 2:
        return pts.copy()
    keep = np.zeros(len(pts), bool)
    keep[[0, -1]] = True
    stack = [(0, len(pts) - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        d = point_segment_distance(pts[i + 1:j], pts[i], pts[j])[:, 0]
        k = int(np.argmax(d))
        if d[k] > tolerance_m:
            k += i + 1
            keep[k] = True
            stack += [(i, k), (k, j)]
    return pts[keep]


def _cross(o, p, q):
    """The z component of (p - o) x (q - o), over the last axis of 2-vectors (its sign says
    on which side of o-p the point q lies)."""
    return (p[..., 0] - o[..., 0]) * (q[..., 1] - o[..., 1]) - (
        p[..., 1] - o[..., 1]) * (q[..., 0] - o[..., 0])


def segments_cross(a1, b1, a2, b2, closed: bool = False) -> np.ndarray:
    """(N, M) mask: segment i of (a1, b1) properly crosses segment j of (a2, b2). `closed`:
    touching counts too (an end on the other segment, a ray through a vertex where two walls
    meet), at the price of collinear segments counting even when apart; `segments_touch`
    is exact, and slower."""
    A1, B1 = a1[:, None, :], b1[:, None, :]
    A2, B2 = a2[None, :, :], b2[None, :, :]
    d1, d2 = _cross(A2, B2, A1), _cross(A2, B2, B1)
    d3, d4 = _cross(A1, B1, A2), _cross(A1, B1, B2)
    if closed:
        return (d1 * d2 <= 0) & (d3 * d4 <= 0)
    return (d1 * d2 < 0) & (d3 * d4 < 0)


def self_intersection(points) -> tuple[int, int] | None:
    """Indices (i, j) of two non-adjacent legs of a polyline that cross, or None."""
    pts = np.asarray(points, float)
    a, b = pts[:-1], pts[1:]
    hits = segments_cross(a, b, a, b)
    hits &= np.abs(np.subtract.outer(np.arange(len(a)), np.arange(len(a)))) > 1
    if not hits.any():
        return None
    i, j = np.argwhere(hits)[0]
    return int(i), int(j)


def offset_polyline(points, offset_m) -> np.ndarray:
    """The polyline moved sideways by `offset_m` (per vertex or scalar; > 0 to the right).

    Right of the direction of travel is starboard: (dx, dy) -> (-dy, dx) in NED. Vertices use
    mitred normals (capped at 2x) so straight legs stay parallel to the original.
    """
    pts = np.asarray(points, float)
    d = np.diff(pts, axis=0)
    d /= np.hypot(*d.T)[:, None]
    n_leg = np.column_stack([-d[:, 1], d[:, 0]])
    n = np.vstack([n_leg[:1], n_leg[:-1] + n_leg[1:], n_leg[-1:]])
    n /= np.maximum(np.hypot(*n.T), 1e-12)[:, None]
    cos_half = np.concatenate([[1.0], np.einsum("ij,ij->i", n[1:-1], n_leg[1:]), [1.0]])
    scale = 1.0 / np.clip(cos_half, 0.5, 1.0)
    off = np.broadcast_to(np.asarray(offset_m, float), (len(pts),))
    return pts + n * (off * scale)[:, None]


def clip_segments_to_circle(a, b, centre, radius_m: float) -> np.ndarray:
    """The parts of segments a-b inside a circle, as (M, 4) rows (x_c, y_c, theta, length)."""
    a, b = np.asarray(a, float).reshape(-1, 2), np.asarray(b, float).reshape(-1, 2)
    c = np.asarray(centre, float).reshape(-1)[:2]
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    f = a - c
    bq = np.einsum("ij,ij->i", f, d)
    disc = bq * bq - dd * (np.einsum("ij,ij->i", f, f) - radius_m**2)
    root = np.sqrt(np.maximum(disc, 0.0))
    safe = np.where(dd > 0, dd, 1.0)
    t0 = np.clip((-bq - root) / safe, 0.0, 1.0)
    t1 = np.clip((-bq + root) / safe, 0.0, 1.0)
    keep = (disc > 0) & (t1 > t0)
    p0, p1 = (a + t0[:, None] * d)[keep], (a + t1[:, None] * d)[keep]
    dv = p1 - p0
    return np.column_stack([(p0 + p1) / 2.0, np.arctan2(dv[:, 1], dv[:, 0]),
                            np.hypot(*dv.T)]).reshape(-1, 4)


def polygon_area(ring) -> float:
    """Signed area of a polygon (K, 2), last point not repeated: > 0 when its vertices turn
    from north toward east (clockwise on a map), < 0 the other way, 0 when they are collinear."""
    p = np.asarray(ring, float).reshape(-1, 2)
    q = np.roll(p, -1, axis=0)
    return float(0.5 * np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def points_in_polygon(points, ring, boundary_m: float = 1e-9) -> np.ndarray:
    """(N,) mask: each point lies strictly inside the polygon ring (K, 2), farther than
    `boundary_m` from its edges. Even-odd rule; a point on the boundary is outside."""
    p = np.asarray(points, float).reshape(-1, 2)
    a = np.asarray(ring, float).reshape(-1, 2)
    b = np.roll(a, -1, axis=0)
    straddle = (a[None, :, 1] > p[:, None, 1]) != (b[None, :, 1] > p[:, None, 1])
    dy = np.where(b[:, 1] != a[:, 1], b[:, 1] - a[:, 1], 1.0)
    x_at = a[None, :, 0] + (p[:, None, 1] - a[None, :, 1]) * (b[:, 0] - a[:, 0]) / dy
    inside = ((straddle & (p[:, None, 0] < x_at)).sum(axis=1) % 2) == 1
    return inside & (point_segment_distance(p, a, b).min(axis=1) > boundary_m)


def segments_touch(a1, b1, a2, b2, tol_m: float = 1e-9) -> np.ndarray:
    """(N, M) mask: segment i of (a1, b1) and segment j of (a2, b2) have a point in common
    (a proper crossing, or an end of one within `tol_m` of the other, collinear overlaps
    included). Unlike `segments_cross`, a path through a wall's vertex counts. Only pairs
    whose bounding boxes, grown by `tol_m`, overlap are tested (no other pair can touch):
    a canal's water outline of a thousand legs is checked in milliseconds, not seconds."""
    a1, b1 = np.asarray(a1, float).reshape(-1, 2), np.asarray(b1, float).reshape(-1, 2)
    a2, b2 = np.asarray(a2, float).reshape(-1, 2), np.asarray(b2, float).reshape(-1, 2)
    lo1, hi1 = np.minimum(a1, b1) - tol_m, np.maximum(a1, b1) + tol_m
    lo2, hi2 = np.minimum(a2, b2), np.maximum(a2, b2)
    near = ((lo1[:, None, 0] <= hi2[None, :, 0]) & (lo2[None, :, 0] <= hi1[:, None, 0])
            & (lo1[:, None, 1] <= hi2[None, :, 1]) & (lo2[None, :, 1] <= hi1[:, None, 1]))
    i, j = np.nonzero(near)
    touch = np.zeros(near.shape, bool)
    if len(i):
        touch[i, j] = segment_pairs_touch(a1[i], b1[i], a2[j], b2[j], tol_m)
    return touch


def segment_pairs_touch(a1, b1, a2, b2, tol_m: float = 1e-9) -> np.ndarray:
    """(K,) mask: segment k of (a1, b1) and segment k of (a2, b2) have a point in common,
    as `segments_touch` decides it for every pair (its reference is that all-pairs form)."""
    def distance(p, a, b):
        ab = b - a
        denom = np.einsum("ij,ij->i", ab, ab)
        t = np.einsum("ij,ij->i", p - a, ab) / np.where(denom > 0, denom, 1.0)
        closest = a + np.clip(t, 0.0, 1.0)[:, None] * ab
        return np.linalg.norm(p - closest, axis=-1)

    touch = ((_cross(a2, b2, a1) * _cross(a2, b2, b1) < 0)
             & (_cross(a1, b1, a2) * _cross(a1, b1, b2) < 0))
    touch |= distance(a1, a2, b2) <= tol_m
    touch |= distance(b1, a2, b2) <= tol_m
    touch |= distance(a2, a1, b1) <= tol_m
    touch |= distance(b2, a1, b1) <= tol_m
    return touch


def polyline_self_touch(points, tol_m: float = 1e-9, closed: bool = False) -> tuple[int, int] | None:
    """Indices (i, j) of two non-adjacent legs of a polyline that cross or touch (a vertex on
    another leg counts, unlike `self_intersection`), or None. `closed`: the last point is the
    first one again, so the first and last legs are adjacent too. No repeated points expected."""
    pts = np.asarray(points, float).reshape(-1, 2)
    a, b = pts[:-1], pts[1:]
    hits = segments_touch(a, b, a, b, tol_m)
    k = np.arange(len(a))
    hits &= np.abs(np.subtract.outer(k, k)) > 1
    if closed and len(a) > 2:
        hits[0, -1] = hits[-1, 0] = False
    if not hits.any():
        return None
    i, j = np.argwhere(hits)[0]
    return int(i), int(j)
