"""The paper's metrics (§IV, DESIGN.md Metrics), as pure functions over a run's arrays.

Clearance is ground truth: distances from the hull circles' centres to the true walls and
obstacles, never to detections.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.geometry import (Polyline, distance_to_polylines, nearest_leg_compiled,
                                 nearest_leg_distance, point_segment_distance,
                                 polyline_legs, polyline_segments, segments_cross)
from controller.nmpc.slack_reference import walls_abeam

HULL_CIRCLE_OFFSETS_M = (2.0, -2.0)
"""Centres of the two hull circles along body x (bow p_b, stern p_s), as in the paper."""


def hull_circle_centres(poses, offsets=HULL_CIRCLE_OFFSETS_M) -> np.ndarray:
    """Centres (N, len(offsets), 2) of the hull circles for poses (N, 3+) of x, y, psi."""
    poses = np.asarray(poses, float).reshape(-1, np.shape(poses)[-1])
    off = np.asarray(offsets, float)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return np.stack([poses[:, 0:1] + off * c[:, None], poses[:, 1:2] + off * s[:, None]], axis=-1)


def clearance(poses, outlines, offsets=HULL_CIRCLE_OFFSETS_M) -> np.ndarray:
    """Distance (N, n_circles) from each hull circle centre to the nearest true outline."""
    centres = hull_circle_centres(poses, offsets)
    n, k = centres.shape[:2]
    return distance_to_polylines(centres.reshape(-1, 2), outlines).reshape(n, k)


class Clearance:
    """`clearance` of one pose at a time against fixed outlines, the same numbers bit for
    bit, in a fraction of the time: by the kernel of `geometry.nearest_leg_distance`, or
    without one the outlines' legs kept in runs of `chunk` with their bounding boxes, and
    only the runs whose box is no farther than the nearest run's nearest leg measured (a
    leg is never nearer than its run's box)."""

    def __init__(self, outlines, offsets=HULL_CIRCLE_OFFSETS_M, chunk: int = 16):
        self._offsets = offsets
        a, b = [], []
        for line in outlines:
            la, lb = polyline_segments(line)
            a.append(la)
            b.append(lb)
        a = np.concatenate(a) if a else np.zeros((0, 2))
        b = np.concatenate(b) if b else np.zeros((0, 2))
        self._a, self._b = a, b
        starts = np.arange(0, len(a), chunk)
        self._run_len = np.diff(np.append(starts, len(a)))
        if len(a):
            lo, hi = np.minimum(a, b), np.maximum(a, b)
            self._lo = np.minimum.reduceat(lo, starts)
            self._hi = np.maximum.reduceat(hi, starts)

    def of(self, pose) -> np.ndarray:
        """(n_circles,) distance from each hull circle centre of `pose` (x, y, psi) to the
        nearest outline (inf: none), as `clearance(pose[None], outlines)[0]`."""
        centres = hull_circle_centres(np.asarray(pose, float)[None, :3], self._offsets)[0]
        if not len(self._a):
            return np.full(len(centres), np.inf)
        if nearest_leg_compiled():  # every leg, compiled: a tenth of the pruning
            return nearest_leg_distance(centres, self._a, self._b)
        gap = np.maximum(np.maximum(self._lo[None] - centres[:, None], centres[:, None]
                                    - self._hi[None]), 0.0)  # (circles, runs, 2)
        box = np.hypot(gap[..., 0], gap[..., 1])
        # Each centre's nearest box's legs bound its distance from above; then every run
        # whose box is within that bound (the margin covers the boxes' rounding).
        runs = np.zeros(box.shape[1], bool)
        runs[np.argmin(box, axis=1)] = True
        best = self._nearest(centres, runs)
        runs = (box <= best[:, None] + 1e-6).any(axis=0)
        return self._nearest(centres, runs)

    def _nearest(self, centres, runs) -> np.ndarray:
        legs = np.repeat(runs, self._run_len)
        return point_segment_distance(centres, self._a[legs], self._b[legs]).min(axis=1)


HULL_LENGTH_M, HULL_BREADTH_M = 7.9, 2.6
"""The hull's waterline rectangle (the paper's boat), centred on the body origin."""


class HullContact:
    """Whether the hull rectangle touches any true outline: the run's collision test.

    The outlines' segments are gathered once; a pose is checked only when a hull circle
    centre is within the rectangle's half diagonal of an outline (the caller's clearance).
    """

    def __init__(self, outlines, length_m: float = HULL_LENGTH_M, breadth_m: float = HULL_BREADTH_M):
        self._a, self._b = polyline_legs(outlines)
        self._half = np.array([length_m / 2, breadth_m / 2])
        self.reach_m = float(np.hypot(*self._half)) + max(abs(o) for o in HULL_CIRCLE_OFFSETS_M)

    def corners(self, pose) -> np.ndarray:
        """The rectangle's corners (4, 2) in the NED plane, bow starboard first, clockwise."""
        hx, hy = self._half
        local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
        c, s = np.cos(pose[2]), np.sin(pose[2])
        return local @ np.array([[c, s], [-s, c]]) + np.asarray(pose[:2], float)

    def touches(self, pose) -> bool:
        """An outline crosses a hull edge, or an outline vertex lies on or inside the hull."""
        if not len(self._a):
            return False
        corners = self.corners(pose)
        edges_a, edges_b = corners, np.roll(corners, -1, axis=0)
        if segments_cross(edges_a, edges_b, self._a, self._b).any():
            return True
        c, s = np.cos(pose[2]), np.sin(pose[2])
        d = self._a - np.asarray(pose[:2], float)
        local = np.stack([d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c], axis=1)
        return bool(np.any(np.all(np.abs(local) <= self._half, axis=1)))


class CanalWidth:
    """The canal's free width abeam of the boat and the boat's offset from its middle, from
    the true outlines (walls and obstacles), for the metrics of separation by place: where the
    canal is at least 2 (R_b + d_p) wide the separation can be kept, where it is narrower the
    best a boat can do is the middle.

    Width is the distance to the nearest outline abeam to port plus to starboard (the nearest
    point within 60 deg of the boat's beam, as `controller.nmpc.slack_reference` measures it);
    outlines farther than `reach_m` are not seen (width inf: open water).
    """

    def __init__(self, outlines, reach_m: float = 50.0):
        a, b = polyline_legs(outlines)
        d = b - a
        length = np.hypot(d[:, 0], d[:, 1])
        keep = length > 1e-9
        a, b, d, length = a[keep], b[keep], d[keep], length[keep]
        self._segments = np.column_stack([(a + b) / 2, np.arctan2(d[:, 1], d[:, 0]), length])
        self._lo, self._hi = np.minimum(a, b), np.maximum(a, b)
        self.reach_m = float(reach_m)
        self._box_reach, self._box = None, None

    def at(self, pose, offsets=HULL_CIRCLE_OFFSETS_M) -> tuple[float, float, float]:
        """(width at the boat's origin, smallest width at the origin and the hull circle
        centres, offset of the origin from the middle: + to starboard of it), metres."""
        pose = np.asarray(pose, float)
        reach = self.reach_m + max(abs(o) for o in offsets)
        if reach != self._box_reach:  # the legs' boxes grown by the reach, once
            self._box_reach, self._box = reach, np.concatenate([self._lo - reach,
                                                                 -(self._hi + reach)], axis=1)
        near = (self._box <= np.r_[pose[:2], -pose[:2]]).all(axis=1)
        points = np.vstack([pose[:2], hull_circle_centres(pose[None, :3], offsets)[0]])
        port, starboard = walls_abeam(points, np.full(len(points), pose[2]), self._segments[near])
        port = np.where(port <= self.reach_m, port, np.inf)
        starboard = np.where(starboard <= self.reach_m, starboard, np.inf)
        width = port + starboard
        offset = 0.5 * (port[0] - starboard[0]) if np.isfinite(width[0]) else 0.0
        return float(width[0]), float(width.min()), float(offset)


def separation_by_place(clearance_m, width_m, width_min_hull_m, offset_m,
                        desired_m: float, dt: float) -> dict:
    """Where the canal is at least 2 x `desired_m` wide over the whole hull, the smallest
    hull-circle clearance; where it is narrower at the boat, how long and how far from the
    middle the boat was. Arrays are per control step (clearance (N, 2))."""
    clear = np.asarray(clearance_m, float).reshape(-1, 2).min(axis=1)
    wide = np.asarray(width_min_hull_m, float) >= 2 * desired_m
    narrow = np.asarray(width_m, float) < 2 * desired_m
    off = np.abs(np.asarray(offset_m, float))[narrow]
    return {
        "min_clearance_where_wide_m": float(clear[wide].min()) if wide.any() else None,
        "time_narrow_s": float(np.count_nonzero(narrow) * dt),
        "mean_centre_offset_narrow_m": float(off.mean()) if off.size else None,
        "max_centre_offset_narrow_m": float(off.max()) if off.size else None,
    }


def summary_round(x, digits: int = 6):
    """Round for a stable, readable summary (the log keeps full precision); None for a
    missing or non-finite value."""
    if x is None or not math.isfinite(x):
        return None
    return round(float(x), digits)


def track_figures(times, clearances, commands, cross_track_m, final_xy, goal_xy,
                  desired_m: float, dt: float) -> dict:
    """A run's figures along its track, as summary.json gives them and in its order:
    duration, least clearance (both circles and each), time below the desired separation,
    control effort, cross-track, distance left to the goal, steps. The closed loop and the
    co-simulation score their runs with it."""
    r = summary_round
    clear = np.array(clearances).reshape(-1, 2)
    min_clear = clear.min(axis=1) if len(clear) else np.array([np.inf])
    duration = (times[-1] + dt) if times else 0.0
    rates = command_rates(np.array(commands).reshape(-1, 2), dt)
    return {
        "duration_s": round(duration, 6),
        "min_clearance_m": r(float(min_clear.min())),
        "min_clearance_bow_m": r(float(clear[:, 0].min())) if len(clear) else None,
        "min_clearance_stern_m": r(float(clear[:, 1].min())) if len(clear) else None,
        "desired_separation_m": desired_m,
        "time_below_desired_s": r(time_below(min_clear, desired_m, dt)),
        "control_effort_Jc": r(control_effort(rates)),
        "mean_cross_track_m": r(float(np.mean(cross_track_m))) if cross_track_m else None,
        "max_cross_track_m": r(float(np.max(cross_track_m))) if cross_track_m else None,
        "final_distance_to_goal_m": r(float(np.hypot(*(np.asarray(final_xy)[:2]
                                                       - np.asarray(goal_xy)[:2])))),
        "steps": len(times),
    }


def separation_figures(clearances, widths, desired_m: float, dt: float) -> dict:
    """The separation by place for summary.json: `narrow_below_m` and
    `separation_by_place` over the run's clearances (N, 2) and widths (N, 3)."""
    clear = np.array(clearances).reshape(-1, 2)
    w = np.array(widths, float).reshape(-1, 3)
    by_place = separation_by_place(clear, w[:, 0], w[:, 1], w[:, 2], desired_m, dt)
    return {"narrow_below_m": 2 * desired_m,
            **{k: summary_round(v) for k, v in by_place.items()}}


def time_below(values, threshold: float, dt: float) -> float:
    """Seconds during which `values` (one per step of dt) lie below `threshold`."""
    return float(np.count_nonzero(np.asarray(values) < threshold) * dt)


def command_rates(commands, dt: float, initial=(0.0, 0.0)) -> np.ndarray:
    """Applied command rates (%/s) from the commands (N, 2) sent every dt seconds."""
    cmds = np.asarray(commands, float).reshape(-1, 2)
    prev = np.vstack([np.asarray(initial, float).reshape(1, 2), cmds[:-1]])
    return (cmds - prev) / dt


def control_effort(rates, weights=(1.0, 1.0)) -> float:
    """J_c = sum_i u_i' R u_i with u the command rates in %/s and R = diag(weights)."""
    rates = np.asarray(rates, float).reshape(-1, 2)
    return float(np.sum(rates**2 * np.asarray(weights, float)))


def cross_track(positions, path: Polyline) -> np.ndarray:
    """Unsigned distance from each position (N, 2) to the waypoint path."""
    return np.array([path.cross_track(p) for p in np.asarray(positions, float).reshape(-1, 2)])


@dataclass(frozen=True)
class TimingStats:
    mean_ms: float
    p99_ms: float
    max_ms: float

    @classmethod
    def of(cls, seconds) -> "TimingStats":
        ms = np.asarray(seconds, float) * 1e3
        if ms.size == 0:
            return cls(0.0, 0.0, 0.0)
        return cls(float(ms.mean()), float(np.percentile(ms, 99)), float(ms.max()))


@dataclass(frozen=True)
class WatchedObstacle:
    """An obstacle whose clearance and first detection the summary reports."""

    name: str
    kind: str
    outline: np.ndarray  # (K + 1, 2) closed outline
    removed_at_s: float | None = None


class ObstacleWatch:
    """Per obstacle: the least hull-circle clearance and when, and how far from the boat it
    was when perception first reported a segment on it (a segment whose middle lies within
    `on_m` of an edge of its outline, within `angle_deg` of that edge's direction)."""

    def __init__(self, obstacles, on_m: float = 0.5, angle_deg: float = 10.0):
        self.obstacles = tuple(obstacles)
        self._legs = [polyline_legs([o.outline]) for o in self.obstacles]
        self._on_m, self._cos = on_m, float(np.cos(np.radians(angle_deg)))
        n = len(self.obstacles)
        self.min_clearance = np.full(n, np.inf)
        self.min_at = np.full(n, np.nan)
        self.first_seen_m = np.full(n, np.nan)
        self.first_seen_at = np.full(n, np.nan)

    def update(self, time_s: float, pose, segments) -> None:
        centres = hull_circle_centres(np.asarray(pose, float)[None, :3])[0]
        segs = np.asarray(segments, float).reshape(-1, 4)
        for k, (o, (a, b)) in enumerate(zip(self.obstacles, self._legs)):
            if o.removed_at_s is not None and time_s >= o.removed_at_s:
                continue
            d = float(nearest_leg_distance(centres, a, b).min())
            if d < self.min_clearance[k]:
                self.min_clearance[k], self.min_at[k] = d, time_s
            if np.isnan(self.first_seen_m[k]) and len(segs) and self._seen(segs, a, b):
                self.first_seen_m[k] = float(point_segment_distance(pose[:2], a, b).min())
                self.first_seen_at[k] = time_s

    def _seen(self, segs, a, b) -> bool:
        dist = point_segment_distance(segs[:, :2], a, b)  # (M, legs)
        edge = b - a
        edge = edge / np.maximum(np.hypot(edge[:, 0], edge[:, 1]), 1e-12)[:, None]
        u = np.column_stack([np.cos(segs[:, 2]), np.sin(segs[:, 2])])
        parallel = np.abs(u @ edge.T) >= self._cos
        return bool(((dist <= self._on_m) & parallel).any())

    def summary(self) -> list[dict]:
        def num(x):
            return None if not np.isfinite(x) else round(float(x), 6)

        return [{"name": o.name, "kind": o.kind, "min_clearance_m": num(self.min_clearance[k]),
                 "min_clearance_at_s": num(self.min_at[k]),
                 "first_detected_m": num(self.first_seen_m[k]),
                 "first_detected_at_s": num(self.first_seen_at[k])}
                for k, o in enumerate(self.obstacles)]


def waiting_episodes(waiting, speed_mps, dt: float, at_rest_mps: float = 0.05,
                     approach_mps: float = 0.3, xy=None) -> dict:
    """How long the controller waited (a stop made for a blocked way or blindness), how long
    of that the boat was held at rest, and the highest speed while held; with the boat's
    positions `xy` (n, 2), the way it made over the ground while waiting beyond each
    episode's net displacement (`swing_while_waiting_m`: a boat that brakes to its stop and
    stems a current there makes none, one that surges to and fro past it the whole of every
    swing back and the way made again).

    Held: from the step the boat comes to rest (below `at_rest_mps`) at its stop point to the
    episode's end. An episode that starts at rest (the obstruction in view at the start) has
    the boat first approach its stop point: once it has made way (above `approach_mps`), it
    is held from when it comes to rest again; one that never makes way (a crawl) is held from
    the start, so its creeping counts."""
    waiting = np.asarray(waiting, bool)
    speed = np.asarray(speed_mps, float)
    held = np.zeros(len(waiting), bool)
    edges = np.flatnonzero(np.diff(np.r_[0, waiting.astype(np.int8), 0]))
    for start, end in zip(edges[::2], edges[1::2]):  # each episode: steps start..end-1
        v = speed[start:end]
        from_k = 0
        made_way = np.flatnonzero(v > approach_mps)
        if v[0] < at_rest_mps and len(made_way):  # at rest at first: the approach is not held
            from_k = made_way[0]
        rest = np.flatnonzero(v[from_k:] < at_rest_mps)
        if len(rest):
            held[start + from_k + rest[0]:end] = True
    out = {
        "time_waiting_s": float(np.count_nonzero(waiting) * dt),
        "time_held_s": float(np.count_nonzero(held) * dt),
        "max_speed_while_held_mps": float(speed[held].max()) if held.any() else None,
    }
    if xy is not None:
        xy = np.asarray(xy, float).reshape(-1, 2)
        swing = 0.0
        for start, end in zip(edges[::2], edges[1::2]):
            run = np.hypot(*np.diff(xy[start:end], axis=0).T).sum()
            swing += run - np.hypot(*(xy[end - 1] - xy[start]))
        out["swing_while_waiting_m"] = float(swing)
    return out


def water_estimate(rows: np.ndarray, target_speed_mps: float, within_mps: float = 0.05,
                   steady_mps: float = 0.1) -> dict:
    """How well the current was estimated. `rows`: per step (time, true N, true E, estimated
    N, estimated E, surge speed). Steady running starts when the boat first comes within
    `steady_mps` of the target speed; reported: when the estimate first came within
    `within_mps` of the truth after that (and how long after), and its error from then on."""
    t, true, est, u = rows[:, 0], rows[:, 1:3], rows[:, 3:5], rows[:, 5]
    error = np.hypot(*(est - true).T)
    steady = np.flatnonzero(np.abs(u - target_speed_mps) <= steady_mps)
    out = {"steady_from_s": float(t[steady[0]]) if len(steady) else None,
           "within_mps": within_mps, "within_at_s": None, "within_after_steady_s": None,
           "mean_error_after_mps": None, "max_error_after_mps": None,
           "final_error_mps": float(error[-1])}
    if not len(steady):
        return out
    close = np.flatnonzero((error <= within_mps) & (t >= t[steady[0]]))
    if len(close):
        k = close[0]
        out.update(within_at_s=float(t[k]), within_after_steady_s=float(t[k] - t[steady[0]]),
                   mean_error_after_mps=float(error[k:].mean()),
                   max_error_after_mps=float(error[k:].max()))
    return out
