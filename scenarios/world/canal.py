"""The canal world: a 2.5-D model of quay walls, what stands behind them, and obstacles.

Everything is vertical prisms over a flat water surface at height 0 (DESIGN.md, LiDAR): a
wall is a polyline face from the water up to its quay top, with a strip of quay (road,
pavement) behind it and a backdrop (buildings, trees) further back; an obstacle (pier, moored
boat, bridge deck) is a polygon between two heights. Heights are metres above the waterline,
positive up; x, y are NED metres. Scenario files (TOML) load into these dataclasses; the
LiDAR simulator renders them and the metrics measure clearance against them.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from controller.errors import InputError
from controller.geometry import (Polyline, clip_segments_to_circle, offset_polyline,
                                 point_segment_distance, points_in_polygon, polygon_area,
                                 polyline_legs, polyline_self_touch, segments_cross,
                                 segments_touch, wrap_angle)

LAND_SIDES = ("left", "right")
OBSTACLE_KINDS = ("pier", "boat", "bridge", "other")
ON_WALL_M = 1e-6  # a point this close to a wall is on it, not on the water


class WorldError(InputError):
    """Bad geometry of one part of the world, kept apart as `owner` ("wall 'quay'"), `key`
    (the argument, e.g. "points") and `detail`, so a file loader can name its own field.
    `walls` holds the indices of the walls involved, if any."""

    def __init__(self, owner: str, key: str, detail: str, walls: tuple[int, ...] = ()):
        super().__init__(f"{owner}: {key}: {detail}")
        self.owner, self.key, self.detail, self.walls = owner, key, detail, walls


def _as_points(value, owner: str, key: str, closed_min: int = 2) -> np.ndarray:
    """A finite (K, 2) float array, read-only, or a WorldError naming `owner` and `key`."""
    def bad(detail):
        return WorldError(owner, key, detail)

    try:
        pts = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise bad("expected a list of [x, y] points in metres") from None
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise bad(f"expected a list of [x, y] points, got shape {pts.shape}")
    if len(pts) < closed_min:
        raise bad(f"needs at least {closed_min} points, got {len(pts)}")
    if not np.all(np.isfinite(pts)):
        raise bad(f"point {int(np.argmin(np.isfinite(pts).all(1)))} is not finite")
    step = np.hypot(*np.diff(pts, axis=0).T)
    if np.any(step <= 0.0):
        i = int(np.argmin(step))
        raise bad(f"repeated point at index {i + 1} ({pts[i, 0]:g}, {pts[i, 1]:g})")
    pts.setflags(write=False)
    return pts


def _check_number(value, what: str, low: float | None = None, strict: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise InputError(f"{what}: expected a finite number, got {value!r}")
    if low is not None and (value <= low if strict else value < low):
        raise InputError(f"{what}: must be {'>' if strict else '>='} {low}, got {value!r}")


@dataclass(frozen=True, eq=False)
class Wall:
    """A vertical quay wall: the face polyline, its top above water, and the land behind it.

    `land_side` says on which side of the polyline's direction the land lies. Behind the
    face runs a quay top (ground at `height_m`) `setback_m` deep, then a backdrop (buildings,
    trees) up to `backdrop_height_m` above water (0: open land, nothing stands there).
    """

    points: np.ndarray  # (K, 2) wall face, NED metres
    height_m: float = 1.5
    land_side: str = "left"
    setback_m: float = 5.0
    backdrop_height_m: float = 8.0
    name: str = "wall"

    def __post_init__(self) -> None:
        what = f"wall {self.name!r}"
        object.__setattr__(self, "points", _as_points(self.points, what, "points"))
        _check_number(self.height_m, f"{what}: height_m", 0.0, strict=True)
        _check_number(self.setback_m, f"{what}: setback_m", 0.0, strict=True)
        _check_number(self.backdrop_height_m, f"{what}: backdrop_height_m", 0.0)
        if self.land_side not in LAND_SIDES:
            raise InputError(f"{what}: land_side must be 'left' or 'right', got {self.land_side!r}")
        closed = len(self.points) > 3 and np.allclose(self.points[0], self.points[-1])
        crossing = polyline_self_touch(self.points, ON_WALL_M, closed=closed)
        if crossing is not None:
            raise WorldError(what, "points", f"the wall crosses itself (legs {crossing[0]} "
                             f"and {crossing[1]})")

    @property
    def land_sign(self) -> float:
        """+1 if the land is to the right of the polyline's direction, -1 if to the left."""
        return 1.0 if self.land_side == "right" else -1.0

    @property
    def backdrop(self) -> np.ndarray | None:
        """The backdrop's front line (the face offset onto the land), or None if open land."""
        if self.backdrop_height_m <= self.height_m:
            return None
        return offset_polyline(self.points, self.land_sign * self.setback_m)


@dataclass(frozen=True, eq=False)
class Obstacle:
    """A prism in the water: a polygon outline between two heights above the waterline.

    Piers and moored boats stand on the water (z_bottom_m = 0); a bridge deck spans the canal
    above it (z_bottom_m = its clearance), so a boat lower than that passes under it. One
    given `remove_at_s` is gone from that time of the run on (a barge that is moved away).
    """

    outline: np.ndarray  # (K, 2) polygon, not repeated at the end
    z_top_m: float = 1.0
    z_bottom_m: float = 0.0
    kind: str = "pier"
    name: str = "obstacle"
    remove_at_s: float | None = None  # simulation time it leaves the water; None: never

    def __post_init__(self) -> None:
        what = f"obstacle {self.name!r}"
        pts = _as_points(self.outline, what, "outline", closed_min=3)
        if np.allclose(pts[0], pts[-1]):
            pts = pts[:-1]
            pts.setflags(write=False)
        object.__setattr__(self, "outline", pts)
        _check_number(self.z_bottom_m, f"{what}: z_bottom_m", 0.0)
        _check_number(self.z_top_m, f"{what}: z_top_m")
        if self.z_top_m <= self.z_bottom_m:
            raise InputError(f"{what}: z_top_m ({self.z_top_m}) must be above z_bottom_m "
                             f"({self.z_bottom_m})")
        if self.kind not in OBSTACLE_KINDS:
            raise InputError(f"{what}: kind must be one of {', '.join(OBSTACLE_KINDS)}, "
                             f"got {self.kind!r}")
        if self.remove_at_s is not None:
            _check_number(self.remove_at_s, f"{what}: remove_at_s", 0.0)
        crossing = polyline_self_touch(self.closed, ON_WALL_M, closed=True)
        if crossing is not None:
            raise WorldError(what, "outline", f"crosses itself (legs {crossing[0]} and {crossing[1]})")
        if abs(polygon_area(self.outline)) < 1e-6:
            raise WorldError(what, "outline", "encloses no area (its points lie on one line)")

    def moved(self, outline: np.ndarray) -> "Obstacle":
        """This obstacle with its outline moved rigidly to `outline` (the same polygon turned
        and shifted, e.g. a vessel's hull at its pose now): a rigid move cannot make an
        outline cross itself or lose its area, so the checks are not run again (a vessel's
        prism is placed every control step)."""
        pts = np.array(outline, float).reshape(-1, 2)
        if pts.shape != self.outline.shape:
            raise ValueError(f"obstacle {self.name!r}: a moved outline has {len(pts)} points, "
                             f"not {len(self.outline)}")
        pts.setflags(write=False)
        out = copy.copy(self)
        object.__setattr__(out, "outline", pts)
        return out

    def present_at(self, time_s: float) -> bool:
        """Whether the obstacle is in the water at simulation time `time_s`."""
        return self.remove_at_s is None or time_s < self.remove_at_s

    @property
    def closed(self) -> np.ndarray:
        """The outline with its first point repeated at the end: (K + 1, 2)."""
        return np.vstack([self.outline, self.outline[:1]])

    def contains(self, xy) -> np.ndarray:
        """Whether each point lies inside the outline (even-odd rule)."""
        p = np.asarray(xy, float).reshape(-1, 2)
        a, b = self.outline, np.roll(self.outline, -1, axis=0)
        straddle = (a[None, :, 1] > p[:, None, 1]) != (b[None, :, 1] > p[:, None, 1])
        dy = np.where(b[:, 1] != a[:, 1], b[:, 1] - a[:, 1], 1.0)
        x_at = a[None, :, 0] + (p[:, None, 1] - a[None, :, 1]) * (b[:, 0] - a[:, 0]) / dy
        return ((straddle & (p[:, None, 0] < x_at)).sum(axis=1) % 2) == 1


@dataclass(frozen=True, eq=False)
class CanalWorld:
    """Walls and obstacles of one canal, plus its centre line for 'distance along the canal',
    and the other vessels moving on it (`scenarios.world.vessels`)."""

    walls: tuple[Wall, ...]
    obstacles: tuple[Obstacle, ...] = ()
    centre_line: np.ndarray | None = None  # (K, 2); None: the walls' mean is not guessed
    name: str = "canal"
    edges: dict = field(init=False, repr=False)
    vessels: tuple = ()  # scenarios.world.vessels.Vessel, each a pose at any time

    def __post_init__(self) -> None:
        object.__setattr__(self, "walls", tuple(self.walls))
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        object.__setattr__(self, "vessels", tuple(self.vessels))
        if not self.walls:
            raise InputError(f"canal {self.name!r}: walls: at least one wall is needed")
        if self.centre_line is not None:
            object.__setattr__(
                self, "centre_line", _as_points(self.centre_line, f"canal {self.name!r}", "centre_line"))
        crossing = walls_crossing(self.walls)
        if crossing is not None:
            i, j, leg_i, leg_j = crossing
            raise WorldError(f"canal {self.name!r}", "walls",
                             f"walls {self.walls[i].name!r} and {self.walls[j].name!r} cross each "
                             f"other (their legs {leg_i} and {leg_j})", walls=(i, j))
        object.__setattr__(self, "edges", self._edge_tables())

    # -- construction -------------------------------------------------------------------
    @classmethod
    def from_centre_line(cls, centre_line, width_m, *, wall_height_m=1.5, setback_m=5.0,
                         backdrop_height_m=8.0, obstacles=(), name="canal") -> "CanalWorld":
        """Two walls at +-width/2 from a centre line.

        `width_m` is a number or a profile: a list of (s_m, width_m) pairs, linearly
        interpolated over the arc length s of the centre line (held constant past its ends).
        Height, setback and backdrop are a number (both banks) or a (left, right) pair.
        """
        centre = _as_points(centre_line, f"canal {name!r}", "centre_line")
        s = Polyline(centre).cumulative
        width = _width_profile(width_m, s, f"canal {name!r}: width_m")
        faces = [offset_polyline(centre, sign * width / 2.0) for sign in (-1.0, 1.0)]
        fold = _offset_fold(centre, width, faces)
        if fold is not None:
            raise WorldError(f"canal {name!r}", "centre_line", fold)

        def side(value, i, what):
            v = value[i] if isinstance(value, (tuple, list)) else value
            _check_number(v, f"canal {name!r}: {what}", 0.0)
            return float(v)

        walls = tuple(
            Wall(face, height_m=side(wall_height_m, i, "wall_height_m"), land_side=land,
                 setback_m=side(setback_m, i, "setback_m"),
                 backdrop_height_m=side(backdrop_height_m, i, "backdrop_height_m"), name=land)
            for i, (face, land) in enumerate(zip(faces, ("left", "right")))
        )
        return cls(walls, tuple(obstacles), centre, name)

    @classmethod
    def from_walls(cls, walls, obstacles=(), centre_line=None, name="canal") -> "CanalWorld":
        """From explicit walls (Wall objects); the centre line is optional."""
        return cls(tuple(walls), tuple(obstacles), centre_line, name)

    # -- queries ------------------------------------------------------------------------
    @cached_property
    def _water(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(ring, open_a, open_b): the water as one polygon, two walls joined at their ends,
        and the joins that are the canal's open ends (segments open_a[i] -> open_b[i]).

        Only when the two walls are the two banks of one stretch: land behind each, outside
        the ring, and each open end across the canal (within 30 deg of square to the walls at
        both its ends). A bank in two pieces, or a quay opposite a longer wall, would give a
        ring that cuts off open water; those worlds go by `_reachable_from_centre_line`.
        """
        if len(self.walls) != 2:
            return None
        a, b = self.walls[0].points, self.walls[1].points
        ends_near = np.hypot(*(a[-1] - b[-1])) + np.hypot(*(b[0] - a[0]))
        ends_far = np.hypot(*(a[-1] - b[0])) + np.hypot(*(b[-1] - a[0]))
        b = b[::-1] if ends_near <= ends_far else b
        ends = [(a[-1], b[0], a[-2] - a[-1], b[1] - b[0]),  # join, and the walls' legs there
                (b[-1], a[0], b[-2] - b[-1], a[1] - a[0])]
        open_a, open_b = [], []
        for p, q, leg_p, leg_q in ends:
            join = q - p
            length = float(np.hypot(*join))
            if length <= ON_WALL_M:
                continue  # the walls meet: a closed end
            for leg in (leg_p, leg_q):
                if abs(float(join @ leg)) > 0.5 * length * float(np.hypot(*leg)):
                    return None  # not across the canal
            open_a.append(p)
            open_b.append(q)
        ring = np.vstack([a, b])
        keep = np.hypot(*(ring - np.roll(ring, 1, axis=0)).T) > ON_WALL_M  # walls that meet
        ring = ring[keep]
        if len(ring) < 3 or polyline_self_touch(np.vstack([ring, ring[:1]]), ON_WALL_M, closed=True):
            return None
        for wall in self.walls:  # land behind each wall lies outside the ring, water inside
            k = len(wall.points) // 2
            p, q = wall.points[k - 1], wall.points[k]
            d = (q - p) / np.hypot(*(q - p))
            right = np.array([-d[1], d[0]])  # to starboard of the wall's direction (NED)
            step = 1e-3 * wall.land_sign * right
            land, water = points_in_polygon(np.array([(p + q) / 2 + step, (p + q) / 2 - step]),
                                            ring, 0.0)
            if land or not water:
                return None
        return ring, np.array(open_a).reshape(-1, 2), np.array(open_b).reshape(-1, 2)

    @property
    def water_ring(self) -> np.ndarray | None:
        """The water as one polygon (K, 2) when the two walls are the banks of one stretch
        (`_water`), else None."""
        return None if self._water is None else self._water[0]

    def off_water(self, points) -> list[str | None]:
        """For each (x, y) point: None if it lies on the open water, else why not ("outside
        the canal", "on wall 'left'", "inside obstacle 'pier'"). Bridges do not count.

        With two walls that are the banks of one stretch the water is `water_ring`: a point
        on a wall is off the water, a point on an open end is on it. Otherwise the way from
        the nearest centre-line point must not touch a wall, nor pass the centre line's ends;
        with no centre line, a point must lie on the water side of its nearest wall.
        """
        pts = np.asarray(points, float).reshape(-1, 2)
        reasons: list[str | None] = [None] * len(pts)
        a, b = polyline_legs(self.wall_polylines())
        owner = np.concatenate([np.full(len(w.points) - 1, i) for i, w in enumerate(self.walls)])
        dist = point_segment_distance(pts, a, b)
        if self._water is not None:
            ring, ends_a, ends_b = self._water
            at_end = np.zeros(len(pts), bool)
            if len(ends_a):
                at_end = point_segment_distance(pts, ends_a, ends_b).min(axis=1) <= ON_WALL_M
            inside = points_in_polygon(pts, ring, ON_WALL_M) | at_end
        elif self.centre_line is not None:
            inside = np.array([self._reachable_from_centre_line(p, a, b) for p in pts], bool)
        else:
            inside = self._water_side_of_nearest_wall(pts, a, b, owner, dist)
        for n, p in enumerate(pts):
            hit = [o for o in self.obstacles if o.z_bottom_m == 0 and o.contains(p)[0]]
            if dist[n].min() <= ON_WALL_M:
                reasons[n] = f"on wall {self.walls[owner[int(np.argmin(dist[n]))]].name!r}"
            elif not inside[n]:
                reasons[n] = "outside the canal"
            elif hit:
                reasons[n] = f"inside obstacle {hit[0].name!r}"
        return reasons

    def _water_side_of_nearest_wall(self, pts, a, b, owner, dist) -> np.ndarray:
        """(N,) mask: each point is on the water side of the wall nearest it (the side away
        from its `land_side`). At a vertex two legs are equally near: the one the point lies
        most squarely off decides (a corner's outside stays outside)."""
        d = b - a
        length = np.hypot(d[:, 0], d[:, 1])
        cross = (d[:, 0] * (pts[:, 1:2] - a[:, 1]) - d[:, 1] * (pts[:, 0:1] - a[:, 0])) / length
        sign = np.array([self.walls[i].land_sign for i in owner])
        near = dist <= dist.min(axis=1, keepdims=True) + 1e-9
        score = np.where(near, np.abs(cross), -np.inf)
        leg = np.argmax(score, axis=1)
        rows = np.arange(len(pts))
        return cross[rows, leg] * sign[leg] < 0.0  # cross > 0: to starboard of the leg

    def _reachable_from_centre_line(self, p, a, b) -> bool:
        """No wall touches the way from the nearest centre-line point to p, and p is not past
        the centre line's ends (True when there is no centre line to go by)."""
        if self.centre_line is None:
            return True
        line = Polyline(self.centre_line)
        s, foot, dist, leg = line.project(p)
        d = self.centre_line[leg + 1] - self.centre_line[leg]
        along = float((p - foot) @ d) / float(np.hypot(*d))
        if (s <= 0.0 and along < -ON_WALL_M) or (s >= line.length and along > ON_WALL_M):
            return False
        return dist <= ON_WALL_M or not segments_touch(foot, p, a, b).any()

    @property
    def changes(self) -> bool:
        """Whether anything in the world changes during a run (an obstacle is removed, a
        vessel moves)."""
        return bool(self.vessels) or any(o.remove_at_s is not None for o in self.obstacles)

    def vessel_obstacles(self, time_s: float) -> tuple:
        """The other vessels' hulls at `time_s`, as prisms (for the LiDAR simulator)."""
        return tuple(v.obstacle_at(time_s) for v in self.vessels)

    def obstacles_present(self, time_s: float) -> np.ndarray:
        """(O,) mask: which obstacles are in the water at simulation time `time_s`."""
        return np.array([o.present_at(time_s) for o in self.obstacles], bool)

    def wall_polylines(self) -> list[np.ndarray]:
        """The true wall faces, (K, 2) each: the ground truth for clearance metrics."""
        return [w.points for w in self.walls]

    def obstacle_outlines(self, air_draft_m: float = np.inf) -> list[np.ndarray]:
        """Closed outlines of the obstacles a boat this tall would hit (bridges it passes under
        are left out when z_bottom_m >= air_draft_m)."""
        return [o.closed for o in self.obstacles if o.z_bottom_m < air_draft_m]

    def surfaces(self, air_draft_m: float = np.inf) -> list[np.ndarray]:
        """Every true vertical surface in the water: wall faces and obstacle outlines."""
        return self.wall_polylines() + self.obstacle_outlines(air_draft_m)

    def surface_edges(self, air_draft_m: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """All legs of `surfaces()` as two (M, 2) endpoint arrays a, b."""
        return polyline_legs(self.surfaces(air_draft_m))

    def clearance(self, points, air_draft_m: float = np.inf) -> np.ndarray:
        """Distance from each (x, y) point to the nearest true surface: shape (N,); 0 inside
        an obstacle (a collision)."""
        a, b = self.surface_edges(air_draft_m)
        d = point_segment_distance(points, a, b).min(axis=1)
        for o in self.obstacles:
            if o.z_bottom_m < air_draft_m:
                d[o.contains(points)] = 0.0
        return d

    def segments_near(self, xy, radius_m: float, air_draft_m: float = np.inf) -> np.ndarray:
        """True surfaces within `radius_m` of a point, clipped to that circle: (M, 4) rows
        (x_c, y_c, theta, length) as detection gives them (the paper's known-walls case)."""
        a, b = self.surface_edges(air_draft_m)
        return clip_segments_to_circle(a, b, xy, radius_m)

    def surface_samples(self, centre, radius_m: float, spacing_m: float = 0.25,
                        air_draft_m: float = np.inf):
        """Points every `spacing_m` along the true surfaces within `radius_m` of `centre`.

        Returns (points (N, 2), directions (N,) rad of the surface there, edge (N,) index into
        `surface_edges(air_draft_m)`); each point stands for `spacing_m` of surface.
        """
        a, b = self.surface_edges(air_draft_m)
        centre = np.asarray(centre, float).reshape(2)
        near = np.flatnonzero(point_segment_distance(centre, a, b)[0] <= radius_m)
        length = np.hypot(*(b[near] - a[near]).T)
        count = np.maximum(np.ceil(length / spacing_m).astype(int), 1)
        edge = np.repeat(near, count)
        frac = (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count) + 0.5)
        frac /= np.repeat(count, count)
        d = b[edge] - a[edge]
        pts = a[edge] + frac[:, None] * d
        inside = np.hypot(*(pts - centre).T) <= radius_m
        return pts[inside], np.arctan2(d[inside, 1], d[inside, 0]), edge[inside]

    def line_of_sight(self, origins, points, edge, air_draft_m: float = np.inf) -> np.ndarray:
        """(N, S) mask: the straight 2-D line from origin s to point n crosses no surface
        other than the point's own edge (an index into `surface_edges(air_draft_m)`)."""
        a, b = self.surface_edges(air_draft_m)
        pts = np.asarray(points, float).reshape(-1, 2)
        origins = np.asarray(origins, float).reshape(-1, 2)
        out = np.zeros((len(pts), len(origins)), bool)
        if not len(pts):
            return out
        reach = np.hypot(*(pts[:, None, :] - origins[None, :, :]).transpose(2, 0, 1)).max()
        for k, o in enumerate(origins):
            cand = np.flatnonzero(point_segment_distance(o, a, b)[0] <= reach)
            back = o - pts
            target = pts + 0.01 * back / np.maximum(np.hypot(*back.T), 1e-9)[:, None]
            blocked = segments_cross(np.broadcast_to(o, pts.shape), target, a[cand], b[cand])
            own = edge[:, None] == cand[None, :]
            out[:, k] = ~(blocked & ~own).any(axis=1)
        return out

    def pose_at(self, s_m: float, offset_m: float = 0.0) -> np.ndarray:
        """(x, y, psi) on the centre line at arc length s, moved `offset_m` to starboard."""
        if self.centre_line is None:
            raise InputError(f"canal {self.name!r}: has no centre line to measure distance along")
        line = Polyline(self.centre_line)
        if not 0.0 <= s_m <= line.length:
            raise InputError(f"canal {self.name!r}: distance along the canal {s_m!r} m is "
                             f"outside 0..{line.length:.1f} m")
        xy, heading = line.at(s_m)
        h = float(heading[0])
        xy = xy[0] + offset_m * np.array([-np.sin(h), np.cos(h)])
        return np.array([xy[0], xy[1], float(wrap_angle(h))])

    @property
    def length_m(self) -> float:
        """Length of the centre line (0 if there is none)."""
        return 0.0 if self.centre_line is None else Polyline(self.centre_line).length

    # -- tables for renderers -----------------------------------------------------------
    def _edge_tables(self) -> dict:
        """Flat edge arrays for the LiDAR simulator: faces, backdrops, obstacles. Each leg
        also says which wall or obstacle it belongs to and on which side of a -> b the solid
        lies (side +1: to the right, starboard of the leg's direction; -1: to the left)."""
        def legs(lines):
            if not lines:
                return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, int)
            a, b = polyline_legs(lines)
            owner = np.concatenate([np.full(len(p) - 1, i) for i, p in enumerate(lines)])
            return a, b, owner

        fa, fb, fo = legs([w.points for w in self.walls])
        backdrops = [(i, w.backdrop) for i, w in enumerate(self.walls) if w.backdrop is not None]
        ba, bb, bo = legs([p for _, p in backdrops])
        bo = np.array([backdrops[k][0] for k in bo], int) if len(bo) else bo
        land = np.array([w.land_sign for w in self.walls])
        return {
            "face": (fa, fb, np.array([self.walls[k].height_m for k in fo]), fo, land[fo]),
            "backdrop": (ba, bb, np.array([self.walls[k].backdrop_height_m for k in bo]),
                         np.array([self.walls[k].height_m for k in bo]), bo, land[bo]),
            "obstacle": obstacle_edges(self.obstacles),
        }


def obstacle_edges(obstacles) -> tuple:
    """Flat edge arrays of obstacle outlines for renderers: (a, b, owner, z_bottom_m,
    z_top_m, side): legs a -> b (M, 2), the index into `obstacles` of each leg's owner (M,),
    the obstacles' heights (O,) and on which side of each leg the inside lies (M,), +1 to
    the right (starboard of a -> b), -1 to the left."""
    obstacles = tuple(obstacles)
    zb = np.array([o.z_bottom_m for o in obstacles], float)
    zt = np.array([o.z_top_m for o in obstacles], float)
    if not obstacles:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, int), zb, zt, np.zeros(0)
    a, b = polyline_legs([o.closed for o in obstacles])
    counts = [len(o.outline) for o in obstacles]
    owner = np.repeat(np.arange(len(obstacles)), counts)
    side = np.repeat([1.0 if polygon_area(o.outline) > 0 else -1.0 for o in obstacles], counts)
    return a, b, owner, zb, zt, side


def walls_crossing(walls) -> tuple[int, int, int, int] | None:
    """(i, j, leg of i, leg of j) of the first two different walls that cross or touch, or
    None. Walls may meet at their ends (a bank made of pieces, a wall ending on another);
    a crossing through a vertex counts."""
    for i in range(len(walls)):
        for j in range(i + 1, len(walls)):
            p, q = walls[i].points, walls[j].points
            hits = segments_cross(p[:-1], p[1:], q[:-1], q[1:])
            on_q = point_segment_distance(p[1:-1], q[:-1], q[1:]) <= ON_WALL_M  # inner vertices
            on_p = point_segment_distance(q[1:-1], p[:-1], p[1:]) <= ON_WALL_M
            hits[1:, :] |= on_q
            hits[:, 1:] |= on_p.T
            if hits.any():
                leg_i, leg_j = np.argwhere(hits)[0]
                return i, j, int(leg_i), int(leg_j)
    return None


def _offset_fold(centre: np.ndarray, width: np.ndarray, faces) -> str | None:
    """Why the walls offset by half the width from a centre line fold, or None. They fold
    where a bend is tighter than the offset (a wall leg then runs backwards), and cross where
    the canal comes back within its width of itself."""
    s = Polyline(centre).cumulative
    ahead = np.diff(centre, axis=0)
    narrower = "make the canal narrower there (width_m / width_profile)"
    for face, side in zip(faces, ("left", "right")):
        back = np.flatnonzero(np.einsum("ij,ij->i", np.diff(face, axis=0), ahead) <= 0.0)
        if len(back):
            k = int(back[0])
            return (f"the {side} wall folds back on itself near s = {s[k]:.0f} m along the "
                    f"centre line: a bend there is tighter than half the width "
                    f"({width[k] / 2:.1f} m); round it wider (corner_radius_m) or {narrower}")
        crossing = polyline_self_touch(face, ON_WALL_M)
        if crossing is not None:
            k = crossing[0]
            return (f"the {side} wall crosses itself near s = {s[k]:.0f} m along the centre "
                    f"line: the canal comes back within its width of itself (a bend or U-turn "
                    f"tighter than half the width, or a loop); widen the bend (corner_radius_m), "
                    f"move the centre line apart, or {narrower}")
    hits = segments_touch(faces[0][:-1], faces[0][1:], faces[1][:-1], faces[1][1:], ON_WALL_M)
    if hits.any():
        k = int(np.argwhere(hits)[0][0])
        return (f"the left and right walls cross near s = {s[k]:.0f} m along the centre line: "
                f"the canal comes back within its width of itself; move the centre line "
                f"apart there, or {narrower}")
    return None


def _width_profile(width_m, s: np.ndarray, what: str) -> np.ndarray:
    """Width at each centre-line vertex from a number or (s, width) pairs."""
    if isinstance(width_m, (int, float)) and not isinstance(width_m, bool):
        _check_number(width_m, what, 0.0, strict=True)
        return np.full(len(s), float(width_m))
    try:
        table = np.array(width_m, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a number or a list of [s_m, width_m] pairs") from None
    if table.ndim != 2 or table.shape[1] != 2 or len(table) < 1:
        raise InputError(f"{what}: expected a number or a list of [s_m, width_m] pairs")
    if not np.all(np.isfinite(table)) or np.any(table[:, 1] <= 0):
        raise InputError(f"{what}: widths must be finite and positive")
    if np.any(np.diff(table[:, 0]) <= 0):
        raise InputError(f"{what}: the s_m values must increase")
    return np.interp(s, table[:, 0], table[:, 1])
