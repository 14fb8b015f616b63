"""Clusters of the LiDAR points that no wall explains: the detections the vessel tracker takes.

    the cropped cloud (detection's height band, own hull and wake cut out), body frame
    -> walls: segments longer than any vessel (`max_vessel_length_m`), alone or as a chain
       of nearly collinear pieces (a bend's chords), and the pieces on the line of one, or
       of one seen in the last `wall_memory_s` (`remember_walls`: the quay between moored
       boats); their points are dropped (within `wall_margin_m`, drawn into a grid)
    -> lone returns dropped, occupancy grid (`cell_m`) dilated by a cell, OpenCV connected
       components; components a detected segment runs through are one (a hull side seen
       at a glancing angle falls apart between the beams' rings)
    -> per component with `min_points` points: its convex hull, the corners where the crop
       may have cut it (the range square, the own hull's and wake's boxes), the segments
       through it, and its box on its longest segment (or principal axis)
    -> all of it in the inertial frame, with the pose, and the nearest return per bearing
       from each LiDAR (`free_space`: did the scan see through the water beyond an end?)

A component longer than any vessel, or lying along a wall's line, is a piece of wall, not a
detection. Points closer than `cell_m` * 2 are always in one cluster, points farther than
`cell_m` * 4 never are (unless a segment joins them), so two vessels side by side a few
metres apart stay two; closer, a component that the tracker's predicted outlines of two
vessels claim is split between them (`split_by_outlines`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property, partial

import numpy as np

from . import opencv, polar_view
from ..kernels import pointer
from .cloud_crop import occupancy_kernel
from .cluster_cells import cluster_kernel, cluster_members_compiled, sociable_points_compiled
from .wall_chains import chain_kernel, chained_walls_compiled
from .polar_view import bearing_bin
from .wall_cells import fraction_on

# `cfg` below is a `tracking.TrackerConfig` (it holds the thresholds); not imported, so that
# the tracker uses this module and not the other way round.


@dataclass(frozen=True, eq=False)
class Clusters:
    """K clusters of one scan, inertial frame. `hulls[k]` is the (h, 2) convex hull of
    cluster k; `cut[k]` (h, 2) gives at each corner the direction in which the crop may have
    cut the object off (the range square, the own hull's and the wake's boxes), zero where
    not; whether an end is hidden behind something is `free_space`'s question. `faces[k]`
    (f, 2, 2): the endpoints of the scan's (non-wall) segments that run through cluster k:
    where one reaches beyond an end of the cluster, the face goes on there unseen (the
    returns between the beams' rings, too sparse to join the cluster)."""

    centre: np.ndarray  # (K, 2) centre of the minimum-area rectangle
    angle: np.ndarray  # (K,) direction of its long side, rad in [-pi/2, pi/2)
    from_side: np.ndarray  # (K,) bool: the angle is a detected segment's (else principal axis)
    size: np.ndarray  # (K, 2) its long and short side, m
    count: np.ndarray  # (K,) points in the cluster
    hulls: tuple
    cut: tuple
    walls: np.ndarray  # (M,) bool: which of the scan's segments were taken for walls
    occluders: np.ndarray  # (N, 2) body-frame returns that can hide something (free_space)
    pose: tuple  # (x, y, psi) the cloud was placed with
    faces: tuple = ()
    # Where the scan is seen from (`TrackerConfig.viewpoints`): (V, 3) body-frame x, y and
    # height of each LiDAR (one row at the origin, height NaN: not known), the own hull's
    # returns (H, 3) body-frame x, y, height, and the height a beam must reach over water.
    viewpoints: np.ndarray = field(default_factory=lambda: np.array([[0.0, 0.0, np.nan]]))
    hull_returns: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    band_top_m: float = 0.0
    # Inertial returns of the confident walls (segments or chains longer than any vessel),
    # when asked for (`collect_wall_points`): what `wall_cells` remembers.
    wall_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    def __len__(self) -> int:
        return len(self.count)

    @cached_property
    def occluder_view(self) -> polar_view.OccluderView:
        """The occluders as each viewpoint sees them: `nearest(k, bins)`, the squared range
        of the nearest per bearing bin (inf: none); made when `free_space` first asks (most
        scans never do)."""
        return polar_view.OccluderView(self.occluders, self.viewpoints)

    @cached_property
    def hull_view(self) -> polar_view.HullView:
        """The own hull's returns as each viewpoint sees them: `slope(k, bins)`, the steepest
        rise (height over range) per bearing bin (-inf: none): a sight line from the unit
        that climbs less than this is cut by the hull (a cabin), one that climbs more passes
        over (a deck below the unit)."""
        return polar_view.HullView(self.hull_returns, self.viewpoints)


def wall_segments(segments: np.ndarray, cfg: "TrackerConfig", known=None) -> np.ndarray:
    """(M,) bool: the segments longer than any vessel, alone or as a chain of pieces whose
    ends meet within `chain_gap_m` at less than `chain_angle_deg` (a bend's chords, a quay
    broken by Hough), and the pieces on the line of one, or of a `known` wall (K, 4) seen
    in earlier scans (within `wall_margin_m`, parallel within `collinear_deg`: the quay
    between and behind moored boats). Pieces meeting at a corner are not chained: a moored
    boat's end face touching the quay stays the boat's."""

    s = np.asarray(segments, float).reshape(-1, 4)
    m = len(s)
    if not m:
        return np.zeros(0, bool)
    wall = chained_walls(s, cfg)
    lines = s[wall]
    if known is not None and len(known):
        lines = np.concatenate([lines, np.asarray(known)[:, :4]])
    if len(lines) and not wall.all():
        # On the line of a wall, however far from it: the same quay behind a moored boat.
        length = s[:, 3]
        half = 0.5 * length[:, None] * np.column_stack([np.cos(s[:, 2]), np.sin(s[:, 2])])
        ends = np.concatenate([s[:, :2] - half, s[:, :2] + half])
        on = _on_lines(ends, np.concatenate([s[:, 2], s[:, 2]]), lines, cfg)
        wall |= (on[:m] & on[m:]).any(axis=1)
    return wall


def chained_walls(s: np.ndarray, cfg: "TrackerConfig") -> np.ndarray:
    """(M,) bool: the confident walls among (M, 4) segments, those longer than any vessel
    alone or as a chain of pieces (see `wall_segments`); by the compiled kernel
    `wall_chains.c` (`chained_walls_numpy` where none can be built)."""
    if not len(s):
        return np.zeros(0, bool)
    lib = chain_kernel()
    if lib is None:
        return chained_walls_numpy(s, cfg)
    return chained_walls_compiled(lib, s, cfg)


def chained_walls_numpy(s: np.ndarray, cfg: "TrackerConfig") -> np.ndarray:
    """`chained_walls`' numpy twin."""
    m = len(s)
    if not m:
        return np.zeros(0, bool)
    length = s[:, 3]
    half = 0.5 * length[:, None] * np.column_stack([np.cos(s[:, 2]), np.sin(s[:, 2])])
    ends = np.concatenate([s[:, :2] - half, s[:, :2] + half])  # end e belongs to e % m
    seg = np.arange(2 * m) % m
    d = ends[:, None, :] - ends[None, :, :]
    close = np.einsum("ijk,ijk->ij", d, d) <= cfg.chain_gap_m ** 2
    ang = np.abs((s[:, 2][:, None] - s[:, 2][None, :] + np.pi / 2) % np.pi - np.pi / 2)
    i, j = np.nonzero(close & (seg[:, None] < seg[None, :]))
    keep = ang[seg[i], seg[j]] <= math.radians(cfg.chain_angle_deg)
    chain = list(range(m))  # union-find over the few links (a few dozen segments at most)

    def root(k):
        while chain[k] != k:
            chain[k] = chain[chain[k]]
            k = chain[k]
        return k

    for a, b in zip(seg[i][keep].tolist(), seg[j][keep].tolist()):
        chain[root(a)] = root(b)
    chain = np.array([root(k) for k in range(m)])
    total = np.bincount(chain, length, minlength=m)
    return (length > cfg.max_vessel_length_m) | (total[chain] > cfg.max_vessel_length_m)


def _on_lines(points: np.ndarray, direction: np.ndarray, lines: np.ndarray,
              cfg: "TrackerConfig") -> np.ndarray:
    """(P, W) bool: point p lies within `wall_margin_m` of the line of segment w (W, 4), at
    most `wall_reach_m` beyond its ends, and direction[p] is parallel to it within
    `collinear_deg`."""
    u = np.column_stack([np.cos(lines[:, 2]), np.sin(lines[:, 2])])  # (W, 2)
    normal = np.column_stack([-u[:, 1], u[:, 0]])
    off = np.abs(points @ normal.T - np.einsum("wk,wk->w", lines[:, :2], normal))  # (P, W)
    along = np.abs(points @ u.T - np.einsum("wk,wk->w", lines[:, :2], u))
    ang = np.abs((direction[:, None] - lines[None, :, 2] + np.pi / 2) % np.pi - np.pi / 2)
    return ((off <= cfg.wall_margin_m) & (along <= 0.5 * lines[:, 3] + cfg.wall_reach_m)
            & (ang <= math.radians(cfg.collinear_deg)))


def remember_walls(memory: np.ndarray, segments: np.ndarray, time_s: float,
                   cfg: "TrackerConfig") -> np.ndarray:
    """The wall lines seen lately, (K, 5) rows (x_c, y_c, theta, length, last seen s): the
    segments longer than any vessel merged into them (collinear: one line, grown to cover
    both), lines unseen for `wall_memory_s` forgotten. Only such segments, not those the
    memory itself made walls: it cannot feed on its own mistakes."""
    mem = [row for row in np.asarray(memory, float).reshape(-1, 5).tolist()
           if time_s - row[4] <= cfg.wall_memory_s]
    for seg in np.asarray(segments, float).reshape(-1, 4).tolist():
        xc, yc, th, ln = seg
        c, s = math.cos(th), math.sin(th)
        for row in mem:
            mx, my, mth, ml, _ = row
            if abs((th - mth + math.pi / 2) % math.pi - math.pi / 2) > math.radians(cfg.collinear_deg):
                continue
            mc, ms = math.cos(mth), math.sin(mth)
            ends = ((xc - 0.5 * ln * c, yc - 0.5 * ln * s), (xc + 0.5 * ln * c, yc + 0.5 * ln * s))
            if max(abs(-ms * (ex - mx) + mc * (ey - my)) for ex, ey in ends) > cfg.wall_margin_m:
                continue
            t = [mc * (ex - mx) + ms * (ey - my) for ex, ey in ends]
            lo, hi = min(-0.5 * ml, *t), max(0.5 * ml, *t)
            mid = 0.5 * (lo + hi)
            row[:5] = mx + mid * mc, my + mid * ms, mth, hi - lo, time_s
            break
        else:
            mem.append([xc, yc, th, ln, time_s])
    return np.array(mem, float).reshape(-1, 5)


def find_clusters(xy_body: np.ndarray, pose, segments: np.ndarray, cfg: "TrackerConfig",
                  known_walls=None, occluders=None, hull_returns=None, wall_cells=None,
                  collect_wall_points: bool = False, outlines=None) -> Clusters:
    """The clusters among cropped body-frame points `xy_body` (N, 2) that no wall segment
    (inertial (M, 4), from the same scan) explains, placed with `pose` (x, y, psi).
    `occluders` (K, 2): body-frame points of every return that can hide something (the crop
    with a taller height band; default `xy_body`), and `hull_returns` (H, 3) body-frame x, y
    and height of the own hull's (when `cfg.viewpoints` places the LiDARs), for `free_space`.
    `known_walls` (K, 4+): wall lines of earlier scans (`remember_walls`); a segment or a
    cluster lying along one is that wall too. `wall_cells` (`wall_cells.WallCells`): where
    walls were seen; a cluster mostly in those cells is wall. `collect_wall_points`: return
    the confident walls' returns (inertial) in `wall_points`, for that memory.
    `outlines` (T, 5): inertial (x, y, axis, length, width) of vessels predicted now; a
    component that two or more of them claim is split between them (`split_by_outlines`)."""
    cv2 = opencv.cv2()
    det = cfg.detection
    x0, y0, psi = (float(v) for v in pose)
    c, s = math.cos(psi), math.sin(psi)
    walls = wall_segments(segments, cfg, known_walls)
    wall_lines = segments[walls]  # this scan's (a remembered line may run on across a side
    # canal's mouth: `behind_a_wall_end` wants the walls seen now)
    lines = wall_lines
    if known_walls is not None and len(known_walls):
        lines = np.concatenate([lines, np.asarray(known_walls)[:, :4]])
    # The points on this scan's walls are left out with the lone returns (below).
    wall_mask = _wall_mask(wall_lines, (x0, y0, c, s), cfg) if walls.any() else None
    wall_points = _NO_POINTS
    if collect_wall_points and len(segments):
        confident = chained_walls(np.asarray(segments, float).reshape(-1, 4), cfg)
        if confident.any():
            on = xy_body[_on_walls(xy_body, segments[confident], (x0, y0, c, s), cfg)]
            wall_points = on @ np.array([[c, s], [-s, c]]) + (x0, y0)
    r = det.range_m
    n = int(math.ceil(2 * r / cfg.cell_m))
    lib = cluster_kernel()
    sociable = sociable_points_numpy if lib is None else partial(sociable_points_compiled, lib)
    xy, i, j, grid = sociable(xy_body, r, cfg.cell_m, n, wall_mask, cfg.wall_cell_m)
    grid = cv2.dilate(grid, np.ones((3, 3), np.uint8))
    n_labels, labels = cv2.connectedComponents(grid, connectivity=8)
    # Pieces of one face that the detector's segment runs through are one cluster (a hull
    # side seen at a glancing angle falls apart between the beams' rings).
    others = segments[~walls]
    comp, seg = _face_pairs(others, labels, (x0, y0, c, s), cfg)
    labels_cv, root = labels, None
    if len(comp) > 1:
        root = np.arange(n_labels)
        first_comp = {}
        for k, m in zip(comp.tolist(), seg.tolist()):
            if m in first_comp:
                a, b = _find(root, first_comp[m]), _find(root, k)
                root[max(a, b)] = min(a, b)
            else:
                first_comp[m] = k
        root = np.array([_find(root, k) for k in range(n_labels)])
        labels = root[labels]
        comp = root[comp]
    ends = _endpoints(others)
    face_of: dict = {}
    for k, m in zip(comp.tolist(), seg.tolist()):
        face_of.setdefault(k, set()).add(m)
    face_of = {k: ends[sorted(v)] for k, v in face_of.items()}
    if lib is not None:
        count, good, order, first = cluster_members_compiled(lib, i, j, labels_cv, root, n_labels,
                                                             cfg.min_points)
    else:
        count, good, order, first = cluster_members_numpy(i, j, labels, n_labels, cfg.min_points)
    side_angle = _side_angles(segments[~walls], labels, n_labels, (x0, y0, c, s, psi), cfg)
    frame = (x0, y0, c, s, psi)
    centre, angle, size, counts, hulls, edges, from_side, faces = [], [], [], [], [], [], [], []
    rot = np.array([[c, s], [-s, c]])  # row vectors: p_inertial = p_body @ rot + (x0, y0)
    pieces = []  # (body-frame points, side angle or NaN, faces, the angle is a side's)
    for k, a in zip(good.tolist(), first.tolist()):
        pts = xy[order[a:a + count[k]]]
        parts = None
        if outlines is not None and len(outlines) > 1:
            parts = split_by_outlines(pts @ rot + (x0, y0), outlines, cfg)
        if parts is None:
            theta = side_angle[k]
            pieces.append((pts, theta, face_of.get(k, _NO_FACES), not math.isnan(theta)))
            continue
        ends_k = face_of.get(k, _NO_FACES)
        face_part = (_box_distance(ends_k.mean(axis=1), outlines[parts[1]]).argmin(axis=1)
                     if len(ends_k) else np.zeros(0, int))
        for m, o in enumerate(parts[1]):  # each on its own vessel's axis (body frame)
            pieces.append((pts[parts[0] == m], half_turn(outlines[o, 2] - psi),
                           ends_k[face_part == m], False))
    for pts, theta, face_k, side in pieces:
        if len(pts) < cfg.min_points:
            continue
        hull = cv2.convexHull(np.ascontiguousarray(pts, np.float32)).reshape(-1, 2).astype(float)
        from_side.append(side)
        if math.isnan(theta):  # no face long enough for a segment: the principal axis
            cov = np.cov(pts.T) if len(pts) > 2 else np.eye(2)
            theta = 0.5 * math.atan2(2 * cov[0, 1], cov[0, 0] - cov[1, 1])
        u = np.array([math.cos(theta), math.sin(theta)])
        v = np.array([-u[1], u[0]])
        pu, pv = hull @ u, hull @ v
        lu, lv = float(pu.max() - pu.min()), float(pv.max() - pv.min())
        mid = 0.5 * (pu.max() + pu.min()) * u + 0.5 * (pv.max() + pv.min()) * v
        if lv > lu:
            theta, lu, lv = theta + math.pi / 2, lv, lu
        inertial = pts @ np.array([[c, s], [-s, c]]) + (x0, y0)
        if lu > cfg.max_vessel_length_m or (len(lines) and _along_wall(hull, theta, lines, frame, cfg)) \
                or (wall_cells is not None and fraction_on(
                    wall_cells, inertial, cfg.wall_cells_m) >= cfg.wall_cells_share) \
                or behind_a_wall_end(inertial,
                                     np.array([math.cos(theta + psi), math.sin(theta + psi)]),
                                     (x0, y0), wall_lines):
            from_side.pop()
            continue  # a piece of wall
        faces.append(face_k)
        centre.append(mid)
        angle.append(theta)
        size.append((lu, lv))
        counts.append(len(pts))
        hulls.append(hull)
    if hulls:  # (all hulls' corners at once, then split)
        split = np.cumsum([len(h) for h in hulls])[:-1]
        edges = np.split(_at_edge(np.concatenate(hulls), cfg), split)
    # To the inertial frame.
    origin = np.array([x0, y0])
    centre = np.asarray(centre, float).reshape(-1, 2) @ rot + origin
    angle = (np.asarray(angle, float) + psi + np.pi / 2) % np.pi - np.pi / 2
    hulls = tuple(h @ rot + origin for h in hulls)
    edges = tuple(e @ rot for e in edges)
    return Clusters(centre, angle, np.asarray(from_side, bool), np.asarray(size, float).reshape(-1, 2),
                    np.asarray(counts, int), hulls, tuple(edges), walls,
                    xy_body if occluders is None else occluders, (x0, y0, psi), tuple(faces),
                    *_viewpoints(cfg, hull_returns), wall_points)


def split_by_outlines(points: np.ndarray, outlines: np.ndarray, cfg: "TrackerConfig"):
    """Two vessels passing close make one component (their hulls a cell or two apart, or
    a segment through both): a track started on it would hold both, and each vessel's own
    track would lose it. If two or more of the predicted `outlines` (T, 5: x, y, axis,
    length, width, inertial), apart from each other, each hold `min_points` of the
    component's inertial `points` (N, 2) within a cell, each point goes to the outline it
    lies nearest: (part of each point (N,), the outlines' rows, one per part); else None."""
    d = _box_distance(points, outlines)  # (N, T)
    held = np.flatnonzero((d <= cfg.cell_m).sum(axis=0) >= cfg.min_points)
    if len(held) < 2:
        return None
    apart = [held[0]]  # (a duplicate track over the same vessel does not split it)
    for o in held[1:].tolist():
        if all(_boxes_apart(outlines[o], outlines[q], cfg.cell_m) for q in apart):
            apart.append(o)
    if len(apart) < 2:
        return None
    apart = np.array(apart)
    return d[:, apart].argmin(axis=1), apart


def _box_distance(points: np.ndarray, outlines: np.ndarray) -> np.ndarray:
    """(N, T) distance of each point (N, 2) outside each box (T, 5: x, y, axis, length,
    width), the Chebyshev way on the box's axes (negative inside)."""
    c, s = np.cos(outlines[:, 2]), np.sin(outlines[:, 2])
    dx = points[:, 0:1] - outlines[:, 0]
    dy = points[:, 1:2] - outlines[:, 1]
    return np.maximum(np.abs(c * dx + s * dy) - 0.5 * outlines[:, 3],
                      np.abs(-s * dx + c * dy) - 0.5 * outlines[:, 4])


def _boxes_apart(a: np.ndarray, b: np.ndarray, shrink_m: float) -> bool:
    """Whether two boxes (x, y, axis, length, width), each less `shrink_m` a side, do not
    overlap (separating axes: the four sides' directions)."""
    def corners(o):
        u = np.array([math.cos(o[2]), math.sin(o[2])])
        v = np.array([-u[1], u[0]])
        hl, hw = max(0.5 * o[3] - shrink_m, 0.0), max(0.5 * o[4] - shrink_m, 0.0)
        return np.array([o[:2] + i * hl * u + j * hw * v for i in (-1, 1) for j in (-1, 1)])

    ca, cb = corners(a), corners(b)
    for o in (a, b):
        for ang in (o[2], o[2] + math.pi / 2):
            n = np.array([math.cos(ang), math.sin(ang)])
            pa, pb = ca @ n, cb @ n
            if pa.max() < pb.min() or pb.max() < pa.min():
                return True
    return False


def half_turn(theta: float) -> float:
    """An undirected axis' direction in [-pi/2, pi/2) (the tracker's too)."""
    return (theta + math.pi / 2) % math.pi - math.pi / 2


def sociable_points_numpy(xy: np.ndarray, r: float, cell: float, n: int, walls=None,
                          wall_cell: float = 1.0):
    """The points (N, 2) in the (n, n) grid of `cell` with its corner at (-r, -r), less the
    lone returns (no other within a cell or so: a ray through a gap, speckle, which would
    stretch the box of the cluster it joins by metres) and, if given, those on the `walls`
    grid (`_wall_mask`, cells of `wall_cell`): (the kept points, their cells i and j, the
    uint8 grid with 1 at their cells). The numpy twin of the kernel `cluster_cells.c`
    (`sociable_points`)."""
    cv2 = opencv.cv2()
    if walls is not None:
        xy = xy[~grid_at_numpy(walls, xy, r, wall_cell)]
    i = np.floor((xy[:, 0] + r) * (1.0 / cell)).astype(np.intp)
    j = np.floor((xy[:, 1] + r) * (1.0 / cell)).astype(np.intp)
    inside = (i >= 0) & (i < n) & (j >= 0) & (j < n)
    xy, i, j = xy[inside], i[inside], j[inside]
    flat = i * n + j
    count = np.bincount(flat, minlength=n * n).reshape(n, n).astype(np.float32)
    company = cv2.boxFilter(count, -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
    social = company[i, j] >= 2
    xy, i, j = xy[social], i[social], j[social]
    grid = np.zeros((n, n), np.uint8)
    grid[i, j] = 1
    return xy, i, j, grid


def cluster_members_numpy(i: np.ndarray, j: np.ndarray, labels: np.ndarray, n_labels: int,
                          min_points: int):
    """The members of each component (`labels` (n, n), 0 the background) among the points
    at cells (i, j): (points per label, the labels with at least `min_points`, the indices
    of those labels' points grouped by label in ascending order and each group in the
    points' order, where each such label's group starts). The numpy twin of the kernel
    `cluster_cells.c` (`cluster_members`)."""
    point_label = labels[i, j]
    count = np.bincount(point_label, minlength=n_labels)
    count[0] = 0  # background (no point has it)
    good = np.flatnonzero(count >= min_points)
    kept = np.flatnonzero(count[point_label] >= min_points)  # (sort only these)
    order = kept[np.argsort(point_label[kept], kind="stable")]
    first = np.searchsorted(point_label[order], good)
    return count, good, order, first


def behind_a_wall_end(xy: np.ndarray, axis: np.ndarray, sensor, walls: np.ndarray,
                      touch_m: float = 1.0, min_angle_deg: float = 45.0,
                      min_depth_m: float = 1.0) -> bool:
    """Whether a cluster's points `xy` (N, 2), long axis `axis` (unit (2,)), are a face that
    runs from a wall into the land behind it, as seen from `sensor`: one end within
    `touch_m` of a wall segment (`walls` (M, 4) rows x_c, y_c, theta, length; all inertial),
    its axis more than `min_angle_deg` across that wall, and its other end at least
    `min_depth_m` beyond the wall's line from the sensor. Nothing floats behind a quay:
    this is the far wall of a side canal seen through its mouth, which grows as the boat
    comes abeam and never makes a segment long enough to be a wall on its own. A boat
    moored alongside lies along the wall; one moored bow-on lies on the water's side."""
    if not len(walls) or len(xy) < 2:
        return False
    t = xy @ axis
    lo, hi = float(t.min()), float(t.max())
    ends = np.stack([xy[t <= lo + touch_m].mean(axis=0), xy[t >= hi - touch_m].mean(axis=0)])
    w = np.column_stack([np.cos(walls[:, 2]), np.sin(walls[:, 2])])  # (M, 2) directions
    n = np.column_stack([-w[:, 1], w[:, 0]])
    half = 0.5 * walls[:, 3]
    across = abs(w @ axis) < math.cos(math.radians(min_angle_deg))  # (M,)
    sensor_side = np.einsum("mk,mk->m", np.asarray(sensor, float) - walls[:, :2], n)
    for near, far in ((0, 1), (1, 0)):
        rel = ends[near] - walls[:, :2]
        along, off = np.einsum("mk,mk->m", rel, w), np.einsum("mk,mk->m", rel, n)
        touching = (np.abs(along) <= half + touch_m) & (np.abs(off) <= touch_m)
        depth = np.einsum("mk,mk->m", ends[far] - walls[:, :2], n)
        behind = (depth * sensor_side < 0.0) & (np.abs(depth) >= min_depth_m)
        if (touching & across & behind).any():
            return True
    return False


def _viewpoints(cfg, hull_returns) -> tuple:
    """Where the scan is seen from and what of the own hull is in the way (see Clusters):
    the LiDARs (`cfg.viewpoints`), else the boat's origin with no hull."""
    if getattr(cfg, "viewpoints", ()):
        hull = np.zeros((0, 3)) if hull_returns is None else np.asarray(hull_returns, float)
        return (np.asarray(cfg.viewpoints, float).reshape(-1, 3), hull.reshape(-1, 3),
                float(cfg.detection.max_height_m))
    return np.array([[0.0, 0.0, np.nan]]), np.zeros((0, 3)), 0.0


def _along_wall(hull: np.ndarray, theta: float, lines: np.ndarray, frame, cfg) -> bool:
    """Whether a cluster (body-frame hull, long side theta) lies along a wall's line: all its
    corners on one line parallel to it (a piece of quay Hough did not make a segment of)."""
    x0, y0, c, s, psi = frame
    pts = hull @ np.array([[c, s], [-s, c]]) + (x0, y0)
    return bool(_on_lines(pts, np.full(len(pts), theta + psi), lines, cfg).all(axis=0).any())


def _side_angles(segments: np.ndarray, labels: np.ndarray, n_labels: int, frame,
                 cfg: "TrackerConfig") -> np.ndarray:
    """(n_labels,) body-frame direction of the longest segment lying in each component (its
    two ends and middle in it), NaN where none does: the hull's side as the line detector
    fitted it, more exact than any box around an L of points (whose hull is a triangle)."""
    x0, y0, c, s, psi = frame
    out = np.full(n_labels, np.nan)
    if not len(segments):
        return out
    r = cfg.detection.range_m
    n = labels.shape[0]
    half = 0.5 * segments[:, 3:4] * np.column_stack([np.cos(segments[:, 2]), np.sin(segments[:, 2])])
    p = np.concatenate([segments[:, :2] - half, segments[:, :2], segments[:, :2] + half])
    b = (p - (x0, y0)) @ np.array([[c, -s], [s, c]])
    i = np.floor((b[:, 0] + r) * (1.0 / cfg.cell_m)).astype(np.intp)
    j = np.floor((b[:, 1] + r) * (1.0 / cfg.cell_m)).astype(np.intp)
    inside = (i >= 0) & (i < n) & (j >= 0) & (j < n)
    which = np.where(inside, labels[np.clip(i, 0, n - 1), np.clip(j, 0, n - 1)], 0)
    which = which.reshape(3, -1)  # (start, middle, end) x segment
    label = np.where((which[0] == which[1]) & (which[1] == which[2]), which[1], 0)
    for m in np.argsort(segments[:, 3]).tolist():  # longest last: it wins
        if label[m]:
            out[label[m]] = segments[m, 2] - psi
    return out


_NO_FACES = np.zeros((0, 2, 2))
_NO_POINTS = np.zeros((0, 2))


def _find(root: np.ndarray, k: int) -> int:
    """Union-find: the root of k (halving the path on the way)."""
    while root[k] != k:
        root[k] = root[root[k]]
        k = int(root[k])
    return k


def _endpoints(segments: np.ndarray) -> np.ndarray:
    """(M, 2, 2) endpoints of (M, 4) segments."""
    u = np.column_stack([np.cos(segments[:, 2]), np.sin(segments[:, 2])])
    half = 0.5 * segments[:, 3:4] * u
    return np.stack([segments[:, :2] - half, segments[:, :2] + half], axis=1)


def _face_pairs(segments: np.ndarray, labels: np.ndarray, frame, cfg: "TrackerConfig"):
    """(component, segment) index pairs: each segment sampled every half cell, the
    components its samples fall in (not the background)."""
    if not len(segments):
        return np.zeros(0, int), np.zeros(0, int)
    x0, y0, c, s = frame
    r = cfg.detection.range_m
    n = labels.shape[0]
    u = np.column_stack([np.cos(segments[:, 2]), np.sin(segments[:, 2])])
    count = np.maximum(np.ceil(segments[:, 3] / (0.5 * cfg.cell_m)).astype(int), 1) + 1
    seg = np.repeat(np.arange(len(segments)), count)
    t = (np.arange(len(seg)) - np.repeat(np.cumsum(count) - count, count)) / np.repeat(count - 1, count)
    pts = segments[seg, :2] + ((t - 0.5) * segments[seg, 3])[:, None] * u[seg]
    b = (pts - (x0, y0)) @ np.array([[c, -s], [s, c]])
    i = np.floor((b[:, 0] + r) * (1.0 / cfg.cell_m)).astype(np.intp)
    j = np.floor((b[:, 1] + r) * (1.0 / cfg.cell_m)).astype(np.intp)
    inside = (i >= 0) & (i < n) & (j >= 0) & (j < n)
    m = len(segments)
    pairs = np.unique(labels[i[inside], j[inside]] * m + seg[inside])
    pairs = pairs[pairs >= m]
    return pairs // m, pairs % m


def _on_walls(xy: np.ndarray, walls: np.ndarray, frame, cfg: "TrackerConfig") -> np.ndarray:
    """(N,) bool: the body-frame points within about `wall_margin_m` of the wall segments
    (inertial) or of their lines up to `wall_extend_m` beyond their ends (where the fit
    stopped short of the wall's last returns, next to a moored boat's end face), drawn as
    thick lines into a grid of `wall_cell_m` (`_wall_mask`; no (N, M) distance table)."""
    return grid_at(_wall_mask(walls, frame, cfg), xy, cfg.detection.range_m, cfg.wall_cell_m)


def _wall_mask(walls: np.ndarray, frame, cfg: "TrackerConfig") -> np.ndarray:
    """The (n, n) uint8 grid of `wall_cell_m` (corner at (-range, -range), body frame) with
    the wall segments (inertial) drawn in as lines `wall_margin_m` thick on either side and
    `wall_extend_m` longer at each end (see `_on_walls`)."""
    cv2 = opencv.cv2()
    x0, y0, c, s = frame
    r = cfg.detection.range_m
    cell = cfg.wall_cell_m
    n = int(math.ceil(2 * r / cell))
    half = (0.5 * walls[:, 3:4] + cfg.wall_extend_m) * np.column_stack(
        [np.cos(walls[:, 2]), np.sin(walls[:, 2])])
    ends = np.concatenate([walls[:, :2] - half, walls[:, :2] + half]) - (x0, y0)
    body = ends @ np.array([[c, -s], [s, c]])  # inertial offsets to the body frame
    # cv2 points are (column, row) = (y, x) cells, in 1/16 of a cell (shift=4).
    px = np.round((body[:, ::-1] + r) * (16.0 / cell) - 8.0).astype(np.int64)
    px = np.clip(px, -(1 << 26), 1 << 26).astype(np.int32)
    mask = np.zeros((n, n), np.uint8)
    thick = 2 * int(round(cfg.wall_margin_m / cell)) + 1
    m = len(walls)
    for k in range(m):
        cv2.line(mask, tuple(px[k].tolist()), tuple(px[k + m].tolist()), 1, thick,
                 cv2.LINE_8, 4)
    return mask


def grid_at(grid: np.ndarray, xy: np.ndarray, r: float, cell: float) -> np.ndarray:
    """(N,) bool: the (n, n) uint8 grid (corner at (-r, -r), cells `cell` wide) at the cell
    of each body-frame point (N, 2), cells clipped into the grid; by the compiled kernel
    `occupancy.c` (`grid_at_numpy` where none can be built)."""
    lib = occupancy_kernel()
    if lib is None or not len(xy):
        return grid_at_numpy(grid, xy, r, cell)
    xy = np.ascontiguousarray(xy, float)
    grid = np.ascontiguousarray(grid, np.uint8)
    out = np.empty(len(xy), np.uint8)
    lib.grid_at(len(xy), pointer(xy), grid.shape[0], float(r), 1.0 / cell, pointer(grid),
                pointer(out))
    return out.astype(bool)


def grid_at_numpy(grid: np.ndarray, xy: np.ndarray, r: float, cell: float) -> np.ndarray:
    """`grid_at`'s numpy twin."""
    n = grid.shape[0]
    i = np.floor((xy[:, 0] + r) * (1.0 / cell)).astype(np.intp)
    j = np.floor((xy[:, 1] + r) * (1.0 / cell)).astype(np.intp)
    np.clip(i, 0, n - 1, out=i)
    np.clip(j, 0, n - 1, out=j)
    return grid[i, j].astype(bool)


def free_space(found: Clusters, points, margin_m: float, spread_bins: int = 0) -> np.ndarray:
    """(K,) bool: the scan saw through each inertial point (K, 2): from one of its
    viewpoints, the nearest return at its bearing (its bin, and with `spread_bins` as many
    either side: the beams lie farther apart than the bins, so a bin between two beams is
    empty even on a wall) lies more than `margin_m` beyond it, or there is none, and the own
    hull does not cut the sight line to it. A point just beyond a cluster's end that is
    free says the end is the object's; one hidden behind a nearer
    return or lying on one (the same surface, out of the crop's band or between the beams'
    rings) says the object may go on there. Seen from the LiDARs themselves (`viewpoints`),
    a wall's piece that ends where the cabin cuts a unit's view is not an object's end; seen
    from the boat's origin, the bearing behind the cabin would look like open water."""
    x0, y0, psi = found.pose
    c, s = math.cos(psi), math.sin(psi)
    d = np.asarray(points, float).reshape(-1, 2) - (x0, y0)
    bx, by = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    free = np.zeros(len(bx), bool)
    for k, (vx, vy, vz) in enumerate(found.viewpoints.tolist()):
        ux, uy = bx - vx, by - vy
        dist = np.hypot(ux, uy)
        bins = bearing_bin(ux, uy)
        if spread_bins:
            aside = (bins + np.arange(-spread_bins, spread_bins + 1)[:, None]) % polar_view.N_BINS
            nearest = found.occluder_view.nearest(k, aside.ravel()).reshape(aside.shape).min(axis=0)
        else:
            nearest = found.occluder_view.nearest(k, bins)
        seen = nearest > (dist + margin_m) ** 2
        if math.isfinite(vz) and len(found.hull_returns):  # the sight line to the band's top
            seen &= found.hull_view.slope(k, bins) < (found.band_top_m - vz) / np.maximum(
                dist, 1e-3)
        free |= seen  # (as from the origin, no return at a bearing counts as open water)
    return free


def _at_edge(hull: np.ndarray, cfg: "TrackerConfig") -> np.ndarray:
    """(h, 2) body-frame directions in which the crop cut the object off at each hull corner
    within `edge_m` of where it cuts the view (out of the range square, into the own hull's
    and the wake's boxes); zero elsewhere."""
    det = cfg.detection
    e = cfg.edge_m
    x, y = hull[:, 0], hull[:, 1]
    out = np.zeros((len(hull), 2))
    r = det.range_m - e
    out[x >= r, 0] = 1.0
    out[x <= -r, 0] = -1.0
    out[y >= r, 1] = 1.0
    out[y <= -r, 1] = -1.0
    hx0, hx1 = det.hull_x_m
    for x0, x1, half in ((hx0, hx1, det.hull_half_width_m),
                         (hx0 - det.wake_length_m, hx0, det.wake_half_width_m)):
        near = (x >= x0 - e) & (x <= x1 + e) & (np.abs(y) <= half + e)
        if near.any():  # toward the box: the side of it the corner is nearest
            gaps = np.column_stack([x[near] - x1, x0 - x[near], np.abs(y[near]) - half])
            side = np.argmax(gaps, axis=1)  # the box face the corner lies beyond
            into = np.zeros((int(near.sum()), 2))
            into[side == 0, 0] = -1.0
            into[side == 1, 0] = 1.0
            into[side == 2, 1] = -np.sign(y[near][side == 2])
            out[near] = into
    return out
