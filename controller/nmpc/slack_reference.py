"""The slack's reference: the clearance the canal itself forces the boat to give up.

Where the free width between two walls is below 2 (R_b + d_p), every path through gives up part
of the separation, and the OCP's slack has to take it. Paid for from 0 with the paper's
rho s^2, that unavoidable part cost rho s^2 for every 1 s stage inside the stretch, so the
finite horizon traded it against progress: it planned to slow down before the stretch and
sprint through it (fewer stages inside), and in closed loop only the slowing down was carried
out, since the sprint always lay ahead (the bench's canal: 2.0 -> 0.9 m/s before a 9 m stretch
at rho = 1e4, worse with a larger rho; the narrow scenario's boat stopped). So the slack is paid
for from this forced value instead, rho (s_i - sbar_i)^2: the unavoidable violation is free,
every metre beyond it (the boat off the middle) costs what it did, and wherever the canal is
wide enough sbar_i = 0 and the cost is the paper's. A more negative slack only lets the boat
closer to the walls, never pushes it there, so a reference on the generous side is safe; one
on the stingy side is paid for and brings the old incentive back, in proportion.

sbar(q) at a path point q: midway between the walls abeam to port and to starboard, the largest
separation m' with which the OCP's super-ellipses (half axes l/2 + m' and m') leave that point
free, less R_b + d_p (the distance alone is not enough: near a steep segment's ends the power-4
shape reaches up to about 0.6 m further). The stage's value is the most negative sbar over the
stretch of path the stage may lie on: from its reference point to its place in the warm start
(they differ when the boat lags), widened by the hull circles' offsets and half a stage's
travel, so neither circle of the predicted hull meets an unpaid narrowing. The segments are the
ones in the OCP's slots.
"""

from __future__ import annotations

import numpy as np

from ..kernels import pointer
from .path_geometry import geometry_kernel
from .reference import WaypointPath

_ABEAM_COS = 0.5  # a segment's nearest point counts as a side wall within 60 deg of the normal


class _Frames:
    """Points (n, 2) with path headings (n,) seen from segments (M, 4): each point's offsets
    along and across each segment, its distance to each (the vector to its nearest point),
    and the path's starboard normal in each segment's frame."""

    def __init__(self, points, headings, segments):
        seg = np.asarray(segments, float)
        self._ex, self._ey = ex, ey = np.cos(seg[:, 2]), np.sin(seg[:, 2])
        dx = points[:, 0:1] - seg[:, 0]  # (n, M)
        dy = points[:, 1:2] - seg[:, 1]
        self.along = dx * ex + dy * ey
        self.across = dy * ex - dx * ey
        self._headings = headings
        self.half = 0.5 * seg[:, 3]
        # point -> nearest point (np.minimum/maximum: np.clip costs 5x as much on small arrays)
        self.va = np.minimum(np.maximum(self.along, -self.half), self.half) - self.along
        self.vc = -self.across

    @property
    def dist(self) -> np.ndarray:
        """Distance (n, M) from each point to each segment (computed when first asked)."""
        if not hasattr(self, "_dist"):
            self._dist = np.hypot(self.va, self.vc)
        return self._dist

    def all_farther_than(self, distance_m: float) -> bool:
        """Every point is at least `distance_m` from every segment (squared distances with a
        margin of 1e-9 for their rounding: True only where `dist` agrees)."""
        va, vc = self.va, self.vc
        return bool((va * va + vc * vc).min() >= distance_m * distance_m * (1.0 + 1e-9))

    @property
    def normal_along(self) -> np.ndarray:
        return self._normal()[0]

    @property
    def normal_across(self) -> np.ndarray:
        return self._normal()[1]

    def _normal(self) -> tuple[np.ndarray, np.ndarray]:
        """The path's starboard normal in each segment's frame (computed when first asked)."""
        if not hasattr(self, "_normals"):
            nx, ny = -np.sin(self._headings)[:, None], np.cos(self._headings)[:, None]
            ex, ey = self._ex, self._ey
            self._normals = nx * ex + ny * ey, ny * ex - nx * ey
        return self._normals

    def walls_abeam(self) -> tuple[np.ndarray, np.ndarray]:
        """Distance (n,) to the nearest wall abeam to port and to starboard (inf if none): a
        segment's nearest point within 60 deg of the path's normal (a wall across the way is
        no side wall)."""
        normal_along, normal_across = self._normal()
        va, vc, dist = self.va, self.vc, self.dist
        side = va * normal_along + vc * normal_across  # its starboard component
        abeam = np.abs(side) >= _ABEAM_COS * dist
        port = np.min(dist, axis=1, where=abeam & (side < 0), initial=np.inf)
        starboard = np.min(dist, axis=1, where=abeam & (side > 0), initial=np.inf)
        return port, starboard


def walls_abeam(points: np.ndarray, headings: np.ndarray,
                segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (n,) from each point (n, 2) to the nearest wall abeam to port and to
    starboard (inf if none) of a path with headings (n,), among segments (M, 4) rows
    (x_c, y_c, theta, length): a segment's nearest point within 60 deg of the normal. By the
    kernel (`path_geometry.c`), or `walls_abeam_numpy`."""
    points = np.asarray(points, float).reshape(-1, 2)
    if len(segments) == 0:
        return np.full(len(points), np.inf), np.full(len(points), np.inf)
    lib = geometry_kernel()
    if lib is None:
        return walls_abeam_numpy(points, headings, segments)
    seg = np.asarray(segments, float).reshape(-1, 4)
    h = np.asarray(headings, float)
    x, y = np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1])
    nx, ny = -np.sin(h), np.cos(h)
    sx, sy = np.ascontiguousarray(seg[:, 0]), np.ascontiguousarray(seg[:, 1])
    ex, ey, half = np.cos(seg[:, 2]), np.sin(seg[:, 2]), 0.5 * seg[:, 3]
    port, starboard = np.empty(len(points)), np.empty(len(points))
    p = pointer
    lib.walls_abeam(len(points), p(x), p(y), p(nx), p(ny), len(seg), p(sx), p(sy), p(ex),
                    p(ey), p(half), _ABEAM_COS, p(port), p(starboard))
    return port, starboard


def walls_abeam_numpy(points: np.ndarray, headings: np.ndarray,
                      segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`walls_abeam`'s numpy twin (the kernel's sines and cosines are numpy's too)."""
    points = np.asarray(points, float).reshape(-1, 2)
    return _Frames(points, np.asarray(headings, float), segments).walls_abeam()


def free_width(points: np.ndarray, headings: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Width (n,) between the nearest walls abeam to port and to starboard of each point
    (inf where one side has none), for points (n, 2) on a path with headings (n,) and segments
    (M, 4) rows (x_c, y_c, theta, length)."""
    port, starboard = walls_abeam(points, headings, segments)
    return port + starboard


def separation_allowed(along: np.ndarray, across: np.ndarray, half: np.ndarray,
                       margin_m: float, newton_steps: int = 4) -> np.ndarray:
    """The largest separation m' <= margin_m (n,) with which each point, at offsets (n, M)
    along and across segments of half length `half` (M,), lies outside every segment's
    super-ellipse (half axes l/2 + m' and m', the OCP's constraint), approached from below.

    Per point and segment, F(m') = (a / (l/2 + m'))^4 + (b / m')^4 - 1 is convex and
    decreasing, and max(|b|, |a| - l/2) is a lower bound of its root: Newton's steps from there
    climb toward the root without passing it, so the result never allows more separation than
    the constraint does.
    """
    a, b = np.abs(along), np.abs(across)
    a2, b2 = a * a, b * b
    a4, b4 = a2 * a2, b2 * b2
    # (x * x) ** 2 rather than x ** 4: numpy's power is ten times slower
    inside = a4 / _pow4(half + margin_m) + b4 / margin_m**4 < 1.0
    if not inside.any():
        return np.full(len(a), float(margin_m))
    m = np.maximum(np.maximum(b, a - half), 1e-6)
    for _ in range(newton_steps):  # on every pair: cheaper than picking the few inside
        big = half + m
        ua, ub = a4 / _pow4(big), b4 / _pow4(m)
        m += (ua + ub - 1.0) / (4.0 * (ua / big + ub / m))
    return np.where(inside, np.minimum(m, margin_m), margin_m).min(axis=1)


def _pow4(x):
    x2 = x * x
    return x2 * x2


def forced_slack_at(points: np.ndarray, headings: np.ndarray, segments: np.ndarray,
                    margin_m: float, slack_min_m: float) -> np.ndarray:
    """The slack (n,) a hull circle needs at the best place across the path through each point:
    midway between the walls abeam, the OCP's super-ellipses (not the distance: near a steep
    segment's ends the power-4 shape reaches up to about 0.6 m further) allow it a separation
    m'; the slack is m' - margin_m, clipped to [slack_min_m, 0]. 0 where a side is open.
    By the compiled kernel (`path_geometry.c`), or `forced_slack_at_numpy`."""
    lib = geometry_kernel()
    if lib is None:
        return forced_slack_at_numpy(points, headings, segments, margin_m, slack_min_m)
    p = np.asarray(points, float).reshape(-1, 2)
    x, y = np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1])
    h = np.ascontiguousarray(headings, float)
    seg = np.ascontiguousarray(segments, float).reshape(-1, 4)
    out = np.empty(len(p))
    scratch = np.empty(6 * max(len(seg), 1))
    lib.forced_slack_at(len(p), pointer(x), pointer(y), pointer(h), len(seg), pointer(seg),
                        float(margin_m), float(slack_min_m), pointer(out), pointer(scratch))
    return out


def forced_slack_at_numpy(points: np.ndarray, headings: np.ndarray, segments: np.ndarray,
                          margin_m: float, slack_min_m: float) -> np.ndarray:
    """`forced_slack_at`'s numpy twin."""
    points = np.asarray(points, float).reshape(-1, 2)
    out = np.zeros(len(points))
    if len(segments) == 0:
        return out
    frames = _Frames(points, np.asarray(headings, float), segments)
    # a super-ellipse reaches at most 0.2 m' beyond the distance (its corners): a point with
    # port + starboard >= 2.5 margin_m needs no slack, and so does one whose nearest wall is
    # 1.25 margin_m away or more (port and starboard are each at least that far): the answer
    # for most of a canal wider than 2.5 margin_m, without the walls abeam
    if frames.all_farther_than(1.25 * margin_m):
        return out
    port, starboard = frames.walls_abeam()
    near = port + starboard < 2.5 * margin_m
    if not near.any():
        return out
    shift = 0.5 * (starboard[near] - port[near])[:, None]  # to the middle, along the normal
    allowed = separation_allowed(frames.along[near] + shift * frames.normal_along[near],
                                 frames.across[near] + shift * frames.normal_across[near],
                                 frames.half, margin_m)
    out[near] = np.maximum(np.minimum(allowed - margin_m, 0.0), slack_min_m)
    return out


def forced_slack(path: WaypointPath, lo_m: np.ndarray, hi_m: np.ndarray, segments: np.ndarray,
                 margin_m: float, slack_min_m: float, spacing_m: float = 1.0,
                 offset=None) -> np.ndarray:
    """Per stage, the most negative forced slack (`forced_slack_at`) over the path's arc
    lengths [lo_m, hi_m] (one interval a stage), sampled every `spacing_m`; `offset(s)`: the
    line the boat follows across the path there (+ to starboard), as the reference's. By the
    compiled kernel (`path_geometry.c`), or `forced_slack_numpy` where there is none."""
    lib = geometry_kernel()
    if lib is None:
        return forced_slack_numpy(path, lo_m, hi_m, segments, margin_m, slack_min_m, spacing_m,
                                  offset)
    lo, hi, out = _stretches(path, lo_m, hi_m)
    if len(segments) == 0 or len(lo) == 0:
        return out
    start, count = _samples(lo, hi, spacing_m)
    d = None
    if offset is not None:
        d = np.ascontiguousarray(offset(start + spacing_m * np.arange(count)), float)
        d = d if d.any() else None
    seg = np.ascontiguousarray(segments, float).reshape(-1, 4)
    scratch = np.empty(4 * count + 6 * len(seg))
    lib.forced_slack_stages(len(lo), pointer(lo), pointer(hi), start, float(spacing_m), count,
                            None if d is None else pointer(d), len(path.leg_length),
                            pointer(path.start), pointer(path.delta), pointer(path.leg_length),
                            pointer(path.cumulative), pointer(path.heading), len(seg),
                            pointer(seg), float(margin_m), float(slack_min_m), pointer(out),
                            pointer(scratch))
    return out


def forced_slack_numpy(path: WaypointPath, lo_m: np.ndarray, hi_m: np.ndarray,
                       segments: np.ndarray, margin_m: float, slack_min_m: float,
                       spacing_m: float = 1.0, offset=None) -> np.ndarray:
    """`forced_slack`'s numpy twin."""
    lo, hi, out = _stretches(path, lo_m, hi_m)
    if len(segments) == 0 or len(lo) == 0:
        return out
    start, count = _samples(lo, hi, spacing_m)
    s = start + spacing_m * np.arange(count)
    points, headings = path.at(s)
    if offset is not None:
        d = np.asarray(offset(s), float)
        if d.any():
            points = points + d[:, None] * np.column_stack([-np.sin(headings), np.cos(headings)])
    forced = forced_slack_at_numpy(points, headings, segments, margin_m, slack_min_m)
    if not forced.any():
        return out
    # each stage's samples: indices first..last (at least one), all inside the sampled range
    first = np.minimum(np.ceil((lo - start) / spacing_m - 1e-9), count - 1).astype(int)
    last = np.maximum(np.minimum(np.floor((hi - start) / spacing_m + 1e-9), count - 1)
                      .astype(int), first)
    idx = np.minimum(first[:, None] + np.arange(int((last - first).max()) + 1), last[:, None])
    return forced[idx].min(axis=1)


def _stretches(path: WaypointPath, lo_m, hi_m):
    """The stages' stretches [lo, hi] clipped to the path, and a zero slack per stage."""
    lo = np.minimum(np.maximum(np.asarray(lo_m, float), 0.0), path.length)
    hi = np.minimum(np.maximum(np.asarray(hi_m, float), lo), path.length)
    return lo, hi, np.zeros(len(lo))


def _samples(lo: np.ndarray, hi: np.ndarray, spacing_m: float) -> tuple[float, int]:
    """The first sample and how many, `spacing_m` apart, cover every stretch."""
    start = float(lo.min())
    return start, int((float(hi.max()) - start) / spacing_m + 1.999999)
