"""The NMPC's reference r_0..r_Np from a waypoint polyline and a target speed (DESIGN.md).

r_0 is the closest point on the path, searched forward from the previous progress so that an
S-bend cannot pull it back; r_i lies i * Ts * u_r further along the polyline, across legs,
with the heading of the leg it falls on unwrapped against the boat's heading, and stops at the
last waypoint (speed 0 there). The paper advanced along the current leg only, which at a bend
runs into the outer wall within the 50 m horizon.
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import InputError, finite_number
from ..geometry import Polyline, unwrap_near
from ..kernels import pointer
from .path_geometry import geometry_kernel


@dataclass(frozen=True)
class Reference:
    """r_0..r_Np as rows [x, y, psi, u, 0, 0, 0, 0], and the progress of r_0 along the path."""

    states: np.ndarray  # (Np + 1, 8)
    progress_m: float  # arc length of r_0
    cross_track_m: float  # distance from the boat to r_0
    at_end: bool  # r_0 is the last waypoint


@dataclass(frozen=True)
class WaypointPath:
    """A waypoint Polyline with its arc lengths and leg headings computed once: the reference
    is queried every control period."""

    polyline: Polyline
    start: np.ndarray  # (L, 2) leg starts
    delta: np.ndarray  # (L, 2) leg vectors
    leg_length: np.ndarray  # (L,)
    cumulative: np.ndarray  # (L + 1,) arc length at each waypoint
    heading: np.ndarray  # (L,) rad, unwrapped along the path (no 2 pi jumps between legs)

    @classmethod
    def from_polyline(cls, polyline: Polyline) -> "WaypointPath":
        pts = polyline.points
        delta = np.diff(pts, axis=0)
        lengths = np.hypot(delta[:, 0], delta[:, 1])
        return cls(polyline, pts[:-1].copy(), delta, lengths,
                   np.concatenate([[0.0], np.cumsum(lengths)]),
                   np.unwrap(np.arctan2(delta[:, 1], delta[:, 0])))

    @property
    def length(self) -> float:
        return float(self.cumulative[-1])

    def project(self, point, s_min: float = 0.0, s_max: float | None = None) -> tuple[float, float]:
        """(s, distance) of the closest point with arc length in [s_min, s_max]. By the
        compiled kernel (`path_geometry.c`), or `project_numpy` where there is none."""
        lib = geometry_kernel()
        if lib is None:
            return self.project_numpy(point, s_min, s_max)
        p = np.asarray(point, float)
        s = ctypes.c_double()
        legs, start, delta, length, cum, _ = self._kernel_arrays
        dist = lib.path_project(float(p[0]), float(p[1]), legs, start, delta, length, cum,
                                float(s_min), float(self.cumulative[-1] if s_max is None
                                                    else s_max), ctypes.byref(s))
        return s.value, dist

    def project_numpy(self, point, s_min: float = 0.0, s_max: float | None = None) -> tuple[float, float]:
        """`project`'s numpy twin."""
        cum, L = self.cumulative, self.leg_length
        s_max = cum[-1] if s_max is None else min(s_max, cum[-1])
        s_min = min(s_min, s_max)
        lo, hi = np.maximum(cum[:-1], s_min), np.minimum(cum[1:], s_max)
        legs = np.nonzero(lo <= hi)[0]
        p = np.asarray(point, float)[:2]
        start, delta = self.start.take(legs, axis=0), self.delta.take(legs, axis=0)
        d = p - start
        along = (d[:, 0] * delta[:, 0] + d[:, 1] * delta[:, 1]) / L[legs]
        s = np.minimum(np.maximum(cum[legs] + along, lo[legs]), hi[legs])
        xy = start + ((s - cum[legs]) / L[legs])[:, None] * delta
        dist = np.hypot(xy[:, 0] - p[0], xy[:, 1] - p[1])
        i = int(np.argmin(dist))
        return float(s[i]), float(dist[i])

    def frame(self, points, s_min: float = 0.0, s_max: float | None = None):
        """Path coordinates of many points (N, 2): arc length s of the closest point with s in
        [s_min, s_max], and the signed offset from it (> 0 to starboard of the path). By the
        compiled kernel (`path_geometry.c`), or `frame_numpy` where there is none."""
        lib = geometry_kernel()
        if lib is None:
            return self.frame_numpy(points, s_min, s_max)
        p = np.asarray(points, float).reshape(-1, 2)
        x, y = np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1])
        s, d = np.empty(len(p)), np.empty(len(p))
        cum = self.cumulative
        lib.path_frame(len(p), pointer(x), pointer(y), len(self.leg_length),
                       pointer(self.start), pointer(self.delta), pointer(self.leg_length),
                       pointer(cum), float(s_min), float(cum[-1] if s_max is None else s_max),
                       pointer(s), pointer(d))
        return s, d

    def frame_numpy(self, points, s_min: float = 0.0, s_max: float | None = None):
        """`frame`'s numpy twin."""
        cum, L = self.cumulative, self.leg_length
        s_max = cum[-1] if s_max is None else min(s_max, cum[-1])
        s_min = min(s_min, s_max)
        legs = np.nonzero((cum[:-1] <= s_max) & (cum[1:] >= s_min))[0]
        p = np.asarray(points, float).reshape(-1, 2)
        start, dx, dy = self.start.take(legs, axis=0), self.delta[legs, 0], self.delta[legs, 1]
        length, at = L[legs], cum[legs]
        px = p[:, 0:1] - start[:, 0]  # (N, legs): no (N, legs, 2) temporary, no np.clip
        py = p[:, 1:2] - start[:, 1]
        along = (px * dx + py * dy) / length
        s = np.minimum(np.maximum(at + along, np.maximum(at, s_min)),
                       np.minimum(cum[legs + 1], s_max))
        t = (s - at) / length
        rx = px - t * dx
        ry = py - t * dy
        best = np.argmin(rx * rx + ry * ry, axis=1)
        rows = np.arange(len(p))
        rx, ry = rx[rows, best], ry[rows, best]
        side = (dx[best] * ry - dy[best] * rx) / length[best]
        offset = np.hypot(rx, ry)
        return s[rows, best], np.where(side >= 0.0, offset, -offset)

    def at(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Points (n, 2) and leg headings (n,) at arc lengths s, clamped to the ends. By the
        compiled kernel (`path_geometry.c`), or `at_numpy` where there is none."""
        lib = geometry_kernel()
        s = np.atleast_1d(np.asarray(s, float))
        if lib is None or s.ndim != 1:
            return self.at_numpy(s)
        s = np.ascontiguousarray(s)
        xy, psi = np.empty((len(s), 2)), np.empty(len(s))
        lib.path_points(len(s), pointer(s), *self._kernel_arrays, pointer(xy), pointer(psi))
        return xy, psi

    def at_numpy(self, s) -> tuple[np.ndarray, np.ndarray]:
        """`at`'s numpy twin."""
        cum = self.cumulative
        s = np.minimum(np.maximum(np.atleast_1d(np.asarray(s, float)), 0.0), cum[-1])
        i = np.minimum(np.searchsorted(cum, s, side="right") - 1, len(self.leg_length) - 1)
        t = (s - cum[i]) / self.leg_length[i]
        # ndarray.take for the rows: a tenth of the time of start[i] on small arrays
        xy = self.start.take(i, axis=0)
        xy += t[:, None] * self.delta.take(i, axis=0)
        return xy, self.heading[i]

    @cached_property
    def _kernel_arrays(self) -> tuple:
        """The leg count and the arrays' addresses the kernels take (start, delta, leg
        lengths, cumulative lengths, headings): the arrays are fixed, so taken once."""
        return (len(self.leg_length), pointer(self.start), pointer(self.delta),
                pointer(self.leg_length), pointer(self.cumulative), pointer(self.heading))


def waypoint_path(waypoints) -> WaypointPath:
    """The path through (K, 2) waypoints, with clear errors; repeated points are dropped."""
    if isinstance(waypoints, Polyline):
        waypoints = waypoints.points
    try:
        pts = np.asarray(waypoints, float)
    except (TypeError, ValueError):
        raise InputError("waypoints: expected a (K, 2) array of (x, y) in metres") from None
    if pts.size == 0:
        raise InputError("waypoints: the list is empty; give at least two points")
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(f"waypoints: expected shape (K, 2), got {pts.shape}")
    if not np.isfinite(pts).all():
        raise InputError("waypoints: contain a NaN or infinite coordinate")
    keep = np.concatenate([[True], np.hypot(*np.diff(pts, axis=0).T) > 1e-9])
    pts = pts[keep]
    if len(pts) < 2:
        raise InputError("waypoints: need at least two distinct points")
    return WaypointPath.from_polyline(Polyline(pts))


def reference_trajectory(path: WaypointPath, position, heading_rad: float, speed_mps: float,
                         horizon: int, step_s: float, progress_m: float = 0.0,
                         search_ahead_m: float | None = None, stop_at_m: float | None = None,
                         decel_mps2: float = 0.15, current=(0.0, 0.0),
                         offset_m: float = 0.0, slow_to=None,
                         back_to_stop: bool = False, back_mps: float = 0.5,
                         heading_along_line: bool = True) -> Reference:
    """r_0..r_horizon for a boat at `position` with `heading_rad`.

    The closest point is searched on arc lengths [progress_m, progress_m + search_ahead_m]
    (the whole rest of the path if None): forward only, so the reference never runs back.
    With `stop_at_m` (an arc length: a blocked way ahead) the reference slows at `decel_mps2`
    so that it comes to rest there, and holds there; one already past it holds where it is,
    or with `back_to_stop` goes back to the stop (behind the boat) astern at `back_mps`,
    braking to rest there: a boat waiting for a blocked way that drifts past its stop is
    brought back, not held wherever it drifts to (held where it was, a boat waiting in a
    bend crept 2 m past its stop, to the inner bank and into it: fuzz seed 1 case 102). (A
    reference at the stop all along drove a boat 3 m past it back at 1.8 m/s astern, 26 m
    past the stop, and on again: a waiting boat surging to and fro, fuzz seed 1 case 69.)
    With a `current` (north, east, m/s) the reference heading is the one that keeps the
    course on the path: the leg's direction turned into the current by the crab angle
    asin(V_across / u_water), as a helmsman holds a boat on a line across a stream; without
    it, the heading weight would pull the boat off its line to hold the leg's direction.
    `offset_m` moves the reference across the path (+ to starboard), as the rules of the road
    ask when meeting or overtaking another vessel (`seamanship`): a number, or a function of
    the arc length (a gap off the path ahead, `passage.Channel`); where it changes, the
    heading is turned along the line it draws (with `heading_along_line`): the leg's heading
    across the ramp over to a gap held a slow boat against the move, at rest behind a kayak.
    `slow_to` (arc length, speed): be down to that speed there, braking at `decel_mps2` (a
    blind opening ahead, `blind_openings`): the reference brakes along the horizon as the
    boat must, not at the speed allowed where it is now (which the NMPC followed with a lag
    that brought a boat to a side canal at 1.4 m/s for 1.0, too fast to stop for the vessel
    that came out of it: fuzz seed 1 case 146).
    """
    speed_mps = finite_number(speed_mps, "target speed")
    if speed_mps < 0:
        raise InputError(f"target speed: must be a non-negative number of m/s, got {speed_mps!r}")
    s_max = None if search_ahead_m is None else progress_m + search_ahead_m
    s0, distance = path.project(position, s_min=progress_m, s_max=s_max)
    t = step_s * np.arange(horizon + 1)
    if back_to_stop and stop_at_m is not None and s0 > stop_at_m:
        back, speed = _stopping(0.0, back_mps, s0 - max(stop_at_m, 0.0), decel_mps2, t)
        s, speed = s0 - back, -speed
    elif slow_to is not None:
        s, speed = _braking(s0, speed_mps, stop_at_m, slow_to, decel_mps2, t)
    elif stop_at_m is None:
        s = s0 + speed_mps * t
        speed = np.full(horizon + 1, speed_mps)
    else:
        s, speed = _stopping(s0, speed_mps, stop_at_m, decel_mps2, t)
    xy, psi = path.at(s)  # leg headings, already continuous along the path
    slope = None
    if not callable(offset_m):
        offset = offset_m
    elif heading_along_line:  # the line's slope too (1 m central), in one call
        offset, ahead, behind = np.split(offset_m(np.concatenate([s, s + 0.5, s - 0.5])), 3)
        slope = ahead - behind
    else:
        offset = offset_m(s)
    if (offset != 0.0) if isinstance(offset, (int, float)) else np.any(offset):  # (np.any
        # of a number costs ten times the comparison)
        xy = xy + np.asarray(offset, float)[..., None] * np.column_stack([-np.sin(psi),
                                                                          np.cos(psi)])
        if slope is not None:  # the heading along the line, not the leg's across its ramp
            psi = psi + np.arctan(slope)
    vn, ve = float(current[0]), float(current[1])
    if vn or ve:
        across = -vn * np.sin(psi) + ve * np.cos(psi)  # to starboard of the leg
        along = vn * np.cos(psi) + ve * np.sin(psi)
        water = np.maximum(speed - along, 0.5)  # the boat's speed through the water
        psi = psi - np.arcsin(np.clip(across / water, -0.7, 0.7))  # at most ~45 deg of crab
    psi = psi + (unwrap_near(psi[0], heading_rad) - psi[0])  # the turn nearest the boat's
    states = np.zeros((horizon + 1, 8))
    states[:, 0:2], states[:, 2] = xy, psi
    states[:, 3] = np.where(s < path.length, speed, 0.0)
    return Reference(states, float(s0), float(distance), bool(s0 >= path.length - 1e-9))


def _braking(s0: float, speed: float, stop_m, slow_to, decel: float, t: np.ndarray,
             samples: int = 400):
    """Arc lengths and speeds at times t of a point from s0 under the speed limit
    v(s) = min(`speed`, sqrt(v_s^2 + 2 decel (s_s - s)) (v_s beyond s_s), sqrt(2 decel
    (stop_m - s))) for `slow_to` = (s_s, v_s) and an optional stop: the time to each arc
    length summed over a fine grid of it, then inverted."""
    at, slow = float(slow_to[0]), float(slow_to[1])
    reach = speed * float(t[-1]) + 1.0
    grid = s0 + np.linspace(0.0, reach, samples)
    v = np.minimum(speed, np.sqrt(slow * slow + 2.0 * decel * np.maximum(at - grid, 0.0)))
    if stop_m is not None:
        v = np.minimum(v, np.sqrt(2.0 * decel * np.maximum(stop_m - grid, 0.0)))
    mean = 0.5 * (v[1:] + v[:-1])
    moving = mean > 1e-6
    dt = np.where(moving, (grid[1] - grid[0]) / np.where(moving, mean, 1.0), np.inf)
    time = np.concatenate([[0.0], np.cumsum(dt)])
    ends = np.flatnonzero(~np.isfinite(time))
    last = int(ends[0]) if len(ends) else samples  # at rest from this sample on
    if last <= 1:
        return np.full_like(t, s0, dtype=float), np.zeros_like(t, dtype=float)
    s = np.interp(t, time[:last], grid[:last])
    return s, np.interp(s, grid, v)


def _stopping(s0: float, speed: float, stop_m: float, decel: float, t: np.ndarray):
    """Arc lengths and speeds at times t of a point that cruises at `speed` from s0, then
    brakes at `decel` to rest at `stop_m`: v(s) = min(speed, sqrt(2 decel (stop_m - s)))."""
    room = max(stop_m - s0, 0.0)
    braking = speed * speed / (2.0 * decel)  # distance needed from cruise to rest
    cruise_s = max(room - braking, 0.0) / speed if speed > 0 else 0.0
    start = min(room, braking)  # distance left to the stop when braking begins
    tau = np.maximum(t - cruise_s, 0.0)
    left = np.maximum(math.sqrt(start) - tau * math.sqrt(0.5 * decel), 0.0) ** 2
    cruising = t < cruise_s
    s = np.where(cruising, s0 + speed * t, s0 + room - left)
    v = np.where(cruising, speed, np.sqrt(2.0 * decel * left))
    return s, np.minimum(v, speed)
