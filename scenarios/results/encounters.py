"""Other vessels, measured: how close each came hull to hull and when, on which side it was
passed, whether the boat kept to the starboard half of the channel while meeting it, and how
well perception tracked it. Ground truth from the scenario, as for every clearance."""

from __future__ import annotations

import math

import numpy as np

from controller.geometry import distance_to_polylines, nearest_leg_distance, segments_cross

from .metrics import HULL_BREADTH_M, HULL_LENGTH_M


def hull_outline(pose, length_m: float = HULL_LENGTH_M, breadth_m: float = HULL_BREADTH_M):
    """The own hull's waterline rectangle (4, 2) at pose (x, y, psi)."""
    a, b = length_m / 2, breadth_m / 2
    local = np.array([[a, b], [-a, b], [-a, -b], [a, -b]])
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.column_stack([pose[0] + c * local[:, 0] - s * local[:, 1],
                            pose[1] + s * local[:, 0] + c * local[:, 1]])


def polygon_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Least distance between two polygons' outlines (K, 2) and (L, 2); 0 when they touch or
    one lies inside the other (a collision)."""
    pa, pb = p, np.roll(p, -1, axis=0)
    qa, qb = q, np.roll(q, -1, axis=0)
    if _circles_meet(p, q) and (segments_cross(pa, pb, qa, qb).any() or _inside(p[0], q)
                                or _inside(q[0], p)):
        return 0.0
    return float(min(nearest_leg_distance(p, qa, qb).min(),
                     nearest_leg_distance(q, pa, pb).min()))


def _circles_meet(p: np.ndarray, q: np.ndarray) -> bool:
    """Whether the circles about the two outlines' first points through their farthest
    points meet: where they do not, the outlines can neither cross nor hold one another."""
    rp = float(np.sqrt(((p - p[0]) ** 2).sum(axis=1).max()))
    rq = float(np.sqrt(((q - q[0]) ** 2).sum(axis=1).max()))
    return math.hypot(*(p[0] - q[0])) <= (rp + rq) * (1.0 + 1e-9) + 1e-9


def _inside(point, ring) -> bool:
    a, b = ring, np.roll(ring, -1, axis=0)
    straddle = (a[:, 1] > point[1]) != (b[:, 1] > point[1])
    dy = np.where(b[:, 1] != a[:, 1], b[:, 1] - a[:, 1], 1.0)
    x_at = a[:, 0] + (point[1] - a[:, 1]) * (b[:, 0] - a[:, 0]) / dy
    return bool(((straddle & (point[0] < x_at)).sum() % 2) == 1)


class EncounterWatch:
    """Per vessel, step by step: hull-to-hull distance, the side it is on, meeting."""

    def __init__(self, vessels):
        self.vessels = tuple(vessels)
        n = len(self.vessels)
        self.min_distance = np.full(n, np.inf)
        self.min_at = np.full(n, np.nan)
        self.side_at_min = [None] * n
        self.meeting_steps = np.zeros(n, int)
        self.meeting_starboard = np.zeros(n, int)

    def update(self, time_s: float, pose, centre_offset_m: float) -> float:
        """Record one step; returns the least hull-to-hull distance to any vessel (inf if
        none). `centre_offset_m`: the boat's offset from the channel's middle (+ starboard)."""
        if not self.vessels:
            return math.inf
        own = hull_outline(pose)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        least = math.inf
        for k, v in enumerate(self.vessels):
            other = v.outline_at(time_s)
            d = polygon_distance(own, other)
            least = min(least, d)
            vp = v.pose_at(time_s)
            rel = vp[:2] - np.asarray(pose[:2], float)
            across = -s * rel[0] + c * rel[1]  # + : on our starboard side
            if d < self.min_distance[k]:
                self.min_distance[k], self.min_at[k] = d, time_s
                self.side_at_min[k] = "starboard" if across > 0 else "port"
            ahead = c * rel[0] + s * rel[1]
            vv = v.velocity_at(time_s)
            opposite = (vv[0] * c + vv[1] * s) < -0.3  # it comes the other way
            if opposite and -v.hull.length_m < ahead < 60.0 and np.isfinite(centre_offset_m):
                self.meeting_steps[k] += 1
                self.meeting_starboard[k] += centre_offset_m > 0.0
        return least

    def summary(self, dt: float) -> list[dict]:
        out = []
        for k, v in enumerate(self.vessels):
            meet = int(self.meeting_steps[k])
            out.append({
                "name": v.name,
                "min_hull_distance_m": None if not np.isfinite(self.min_distance[k])
                else round(float(self.min_distance[k]), 6),
                "min_hull_distance_at_s": None if np.isnan(self.min_at[k])
                else round(float(self.min_at[k]), 3),
                "passed_on": self.side_at_min[k],  # which side of the boat it was on
                "time_meeting_s": round(meet * dt, 3),
                "starboard_half_while_meeting": None if meet == 0
                else round(float(self.meeting_starboard[k]) / meet, 4),
            })
        return out


class TrackingWatch:
    """How well the confirmed tracks followed the true vessels: each confirmed track is
    matched to the nearest true vessel (centre within `match_m`), position and velocity
    errors are pooled; a moving track that matches none is a false vessel. A vessel is in view
    from when a corner of its hull enters the detector's crop (|x|, |y| <= `visible_m` in the
    boat's frame; what lies in between is not checked, so round a bend the delay counts
    from before the first line of sight).

    Tracks that mean no boat: a confirmed track matching no vessel whose centre lies within
    `wall_m` of a true wall (`walls`, polylines) and not within `object_m` of a static object
    in the water (`objects`, outlines: a moored boat, a pier) is a wall taken for a boat,
    moving or not;
    their number, the longest and their total time are counted. Track continuity: each
    vessel is matched to one track a step (the one it had while that is still within
    `match_m` of it, else nearest pairs first); a change of that id is a switch, and another
    track near a matched vessel is a duplicate (one boat as two)."""

    def __init__(self, vessels, match_m: float = 6.0, visible_m: float = 60.0, walls=(),
                 wall_m: float = 1.0, objects=(), object_m: float = 2.0):
        self.vessels = tuple(vessels)
        self.match_m, self.visible_m = match_m, visible_m
        self._pos_err, self._vel_err = [], []
        self.first_visible = [None] * len(self.vessels)
        self.first_confirmed = [None] * len(self.vessels)
        self._false: dict = {}  # track id -> seconds as a false moving vessel
        self.walls, self.wall_m = tuple(walls), wall_m
        self.objects, self.object_m = tuple(objects), object_m  # moored boats, piers: real
        self._on_wall: dict = {}  # track id -> seconds on a wall
        self._ids = [None] * len(self.vessels)  # the id last matched to each vessel
        self._switches = [0] * len(self.vessels)
        self._duplicate: dict = {}  # track id -> seconds as a second track on a vessel
        self.saw_tracks = False

    def update(self, time_s: float, pose, tracks, dt: float) -> None:
        self.saw_tracks = self.saw_tracks or bool(tracks)
        truth = [(v.pose_at(time_s), v.velocity_at(time_s)) for v in self.vessels]
        c, s = np.cos(pose[2]), np.sin(pose[2])
        for k, v in enumerate(self.vessels):
            if self.first_visible[k] is not None:
                continue
            d = v.outline_at(time_s) - np.asarray(pose[:2], float)
            x, y = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
            if np.any((np.abs(x) <= self.visible_m) & (np.abs(y) <= self.visible_m)):
                self.first_visible[k] = time_s
        # One track per vessel, nearest pairs first (each track and vessel used once): the
        # vessel's track this step. A second track near a matched vessel is a duplicate
        # (one boat seen as two), counted apart from the switches of the matched id.
        near = sorted((float(np.hypot(*(np.asarray(tr.position, float) - vp[:2]))), k, i)
                      for i, tr in enumerate(tracks) for k, (vp, _) in enumerate(truth))
        matched, taken = {}, set()
        # A vessel keeps the track it had while that track is still on it (a second track
        # beside it, nearer this step, is a duplicate, not a switch).
        for dist, k, i in near:
            if dist <= self.match_m and tracks[i].id == self._ids[k] and i not in taken \
                    and k not in matched:
                matched[k] = i
                taken.add(i)
        for dist, k, i in near:
            if dist > self.match_m:
                break
            if k not in matched and i not in taken:
                matched[k] = i
                taken.add(i)
        for k, i in matched.items():
            tr = tracks[i]
            if self._ids[k] is not None and self._ids[k] != tr.id:
                self._switches[k] += 1
            self._ids[k] = tr.id
            self._pos_err.append(float(np.hypot(*(np.asarray(tr.position, float)
                                                  - truth[k][0][:2]))))
            self._vel_err.append(float(np.hypot(*(np.asarray(tr.velocity) - truth[k][1]))))
            if self.first_confirmed[k] is None:
                self.first_confirmed[k] = time_s
        for i, tr in enumerate(tracks):
            if i in taken:
                continue
            p = np.asarray(tr.position, float)
            if any(np.hypot(*(p - vp[:2])) <= self.match_m for vp, _ in truth):
                self._duplicate[tr.id] = self._duplicate.get(tr.id, 0.0) + dt
                continue
            if getattr(tr, "moving", True):
                self._false[tr.id] = self._false.get(tr.id, 0.0) + dt
            if self.objects and distance_to_polylines(p, self.objects)[0] <= self.object_m:
                continue  # a static object in the water (a moored boat), not a wall
            if self.walls and distance_to_polylines(p, self.walls)[0] <= self.wall_m:
                self._on_wall[tr.id] = self._on_wall.get(tr.id, 0.0) + dt

    def summary(self) -> dict:
        def rms(x):
            return None if not x else round(float(np.sqrt(np.mean(np.square(x)))), 4)

        delays = [None if v is None or c is None else round(c - v, 3)
                  for v, c in zip(self.first_visible, self.first_confirmed)]
        return {"position_rms_m": rms(self._pos_err), "velocity_rms_mps": rms(self._vel_err),
                "confirmed_after_visible_s": dict(zip((v.name for v in self.vessels), delays)),
                "false_vessel_tracks": len(self._false),
                "longest_false_vessel_s": round(max(self._false.values()), 3)
                if self._false else 0.0,
                "wall_tracks": len(self._on_wall),
                "longest_wall_track_s": round(max(self._on_wall.values()), 3)
                if self._on_wall else 0.0,
                "wall_track_time_s": round(sum(self._on_wall.values()), 3),
                "id_switches": dict(zip((v.name for v in self.vessels), self._switches)),
                "duplicate_tracks": len(self._duplicate),
                "longest_duplicate_s": round(max(self._duplicate.values()), 3)
                if self._duplicate else 0.0}
