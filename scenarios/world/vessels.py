"""Other vessels in the canal: a hull and a motion, as a pure function of simulation time.

A vessel follows a route of waypoints at a speed (starting at `start_s`, waiting where told)
or holds a course and speed from a start point, which may wander (`wander_degps`: a seeded
random walk of the heading, for a kayak's erratic paddling). Its pose at any time comes from
a track integrated once at 0.1 s and interpolated, so the LiDAR simulator, the metrics and
the plots all see the same vessel at the same instant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from controller.errors import InputError
from controller.geometry import Polyline

from .canal import Obstacle

HULL_SHAPES = ("rectangle", "pointed")
TRACK_STEP_S = 0.1


@dataclass(frozen=True)
class Hull:
    """A vessel's waterline outline (length along its heading, beam across) and height."""

    length_m: float
    beam_m: float
    height_m: float = 1.5
    shape: str = "pointed"  # a rectangle, or one with a pointed bow (the last quarter)

    def __post_init__(self) -> None:
        for name in ("length_m", "beam_m", "height_m"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v <= 0:
                raise InputError(f"hull {name}: must be a positive number, got {v!r}")
        if self.shape not in HULL_SHAPES:
            raise InputError(f"hull shape: one of {', '.join(HULL_SHAPES)}, got {self.shape!r}")

    def local_outline(self) -> np.ndarray:
        """(K, 2) outline in the vessel's frame (x forward, y starboard), centred."""
        a, b = self.length_m / 2, self.beam_m / 2
        if self.shape == "rectangle":
            return np.array([[a, b], [-a, b], [-a, -b], [a, -b]])
        shoulder = a - 0.25 * self.length_m
        return np.array([[a, 0.0], [shoulder, b], [-a, b], [-a, -b], [shoulder, -b]])


@dataclass(frozen=True, eq=False)
class Vessel:
    """A vessel: its hull and its track over the run (`times`, `poses` [x, y, psi],
    `velocities` [v_north, v_east]), built by `on_route` or `on_course`."""

    name: str
    hull: Hull
    times: np.ndarray  # (T,)
    poses: np.ndarray  # (T, 3)
    velocities: np.ndarray  # (T, 2)
    motion: str = "route"  # "route" | "course", for messages
    # the pose, outline and prism last asked for, by time: the loop, the LiDAR, the metrics
    # and the log all ask for the same instant several times a step
    _last: dict = field(default_factory=dict, repr=False, compare=False, init=False)

    @classmethod
    def on_route(cls, name: str, hull: Hull, waypoints, speed_mps: float, duration_s: float,
                 start_s: float = 0.0, waits=()) -> "Vessel":
        """Along `waypoints` at `speed_mps` from `start_s`; `waits` (waypoint index, seconds)
        pauses there; it stops at the last waypoint."""
        pts = np.asarray(waypoints, float)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2:
            raise InputError(f"vessel {name!r}: route: needs at least two waypoints")
        if np.any(np.hypot(*np.diff(pts, axis=0).T) <= 0):
            raise InputError(f"vessel {name!r}: route: repeats a waypoint")
        _check_speed(name, speed_mps, start_s)
        line = Polyline(pts)
        wait_at = {int(k): float(s) for k, s in waits}
        times = np.arange(0.0, duration_s + TRACK_STEP_S, TRACK_STEP_S)
        # arc length over time: cruise between waypoints, pause at the waits
        knots_t, knots_s = [start_s], [0.0]
        for k in range(1, len(pts)):
            t_arrive = knots_t[-1] + (line.cumulative[k] - line.cumulative[k - 1]) / speed_mps \
                if speed_mps > 0 else math.inf
            knots_t.append(t_arrive)
            knots_s.append(line.cumulative[k])
            if k in wait_at and math.isfinite(t_arrive):
                knots_t.append(t_arrive + wait_at[k])
                knots_s.append(line.cumulative[k])
        finite = np.isfinite(knots_t)
        s = np.interp(times, np.array(knots_t)[finite], np.array(knots_s)[finite])
        xy, heading = line.at(s)
        heading = np.asarray(heading, float)
        v = np.gradient(s, times) if len(times) > 1 else np.zeros(len(times))
        vel = np.column_stack([v * np.cos(heading), v * np.sin(heading)])
        return cls(name, hull, times, np.column_stack([xy, heading]), vel, "route")

    @classmethod
    def on_course(cls, name: str, hull: Hull, start_xy, course_rad: float, speed_mps: float,
                  duration_s: float, start_s: float = 0.0, wander_degps: float = 0.0,
                  seed: int = 0, distance_m: float | None = None, waits=()) -> "Vessel":
        """From `start_xy` on a course and speed from `start_s` (a wandering course if
        `wander_degps`), stopping after `distance_m` if given; `waits` (metres along the
        course, seconds) are pauses on the way (a kayak resting mid-canal, then going on)."""
        _check_speed(name, speed_mps, start_s)
        times = np.arange(0.0, duration_s + TRACK_STEP_S, TRACK_STEP_S)
        heading = np.full(len(times), float(course_rad))
        if wander_degps:
            heading = heading + _wander(times, wander_degps, seed)
        moving = times >= start_s
        under_way = times - start_s  # the time spent moving since the start, less the pauses
        paused = 0.0
        for at_m, for_s in sorted((float(a), float(b)) for a, b in waits):
            if speed_mps <= 0.0:
                break
            arrive = start_s + at_m / speed_mps + paused
            resting = (times >= arrive) & (times < arrive + for_s)
            moving &= ~resting
            under_way = under_way - np.clip(times - arrive, 0.0, for_s)
            paused += for_s
        if distance_m is not None:
            moving &= under_way * speed_mps < distance_m
        v = np.where(moving, speed_mps, 0.0)
        vel = np.column_stack([v * np.cos(heading), v * np.sin(heading)])
        xy = np.asarray(start_xy, float) + np.vstack(
            [[0.0, 0.0], np.cumsum(vel[:-1] * TRACK_STEP_S, axis=0)])
        return cls(name, hull, times, np.column_stack([xy, heading]), vel, "course")

    # -- queries ------------------------------------------------------------------------
    def pose_at(self, time_s: float) -> np.ndarray:
        """(x, y, psi) at `time_s` (held at the ends of the track)."""
        return self._remembered("pose", time_s, self._pose_at).copy()

    def _remembered(self, what: str, time_s: float, make):
        """`make(time_s)`, made once for the time last asked for."""
        hit = self._last.get(what)
        if hit is None or hit[0] != time_s:
            hit = self._last[what] = (time_s, make(time_s))
        return hit[1]

    def _pose_at(self, time_s: float) -> np.ndarray:
        t = self.times
        i = int(np.clip(np.searchsorted(t, time_s) - 1, 0, len(t) - 2)) if len(t) > 1 else 0
        if len(t) == 1:
            return self.poses[0].copy()
        f = float(np.clip((time_s - t[i]) / (t[i + 1] - t[i]), 0.0, 1.0))
        a, b = self.poses[i], self.poses[i + 1]
        dpsi = (b[2] - a[2] + np.pi) % (2 * np.pi) - np.pi
        return np.array([a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * dpsi])

    def velocity_at(self, time_s: float) -> np.ndarray:
        """(v_north, v_east) at `time_s`."""
        k = int(np.clip(np.searchsorted(self.times, time_s, side="right") - 1, 0,
                        len(self.times) - 1))
        return self.velocities[k].copy()

    def outline_at(self, time_s: float) -> np.ndarray:
        """(K, 2) hull outline in the NED frame at `time_s`."""
        return self._remembered("outline", time_s, lambda t: place(
            self.hull.local_outline(), self._remembered("pose", t, self._pose_at))).copy()

    def obstacle_at(self, time_s: float) -> Obstacle:
        """The hull at `time_s` as a prism for the LiDAR simulator (the hull's prism, checked
        once, moved to the pose)."""
        prism = self._last.get("prism")
        if prism is None:
            prism = self._last["prism"] = Obstacle(self.hull.local_outline(),
                                                   z_top_m=self.hull.height_m, kind="boat",
                                                   name=self.name)
        return self._remembered("obstacle", time_s,
                                lambda t: prism.moved(self.outline_at(t)))


def place(local: np.ndarray, pose) -> np.ndarray:
    """Points (K, 2) of a body frame (x forward, y starboard) at pose (x, y, psi) in NED."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.column_stack([pose[0] + c * local[:, 0] - s * local[:, 1],
                            pose[1] + s * local[:, 0] + c * local[:, 1]])


def _check_speed(name: str, speed_mps: float, start_s: float) -> None:
    for what, v in (("speed_mps", speed_mps), ("start_s", start_s)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise InputError(f"vessel {name!r}: {what}: must be a number >= 0, got {v!r}")


def _wander(times: np.ndarray, degps: float, seed: int) -> np.ndarray:
    """A seeded random walk of the heading (rad), `degps` per sqrt(s), pulled back gently
    (an Ornstein-Uhlenbeck walk with a 20 s memory) so it wanders about its course."""
    rng = np.random.default_rng(seed)
    dt = TRACK_STEP_S
    sigma = math.radians(degps) * math.sqrt(dt)
    out = np.zeros(len(times))
    for k in range(1, len(times)):
        out[k] = out[k - 1] * (1.0 - dt / 20.0) + sigma * rng.standard_normal()
    return out
