"""Safe speed past a blind opening (COLREG Rules 6 and 9(f)): slow down where a side canal
opens off the route behind a wall the boat cannot see past.

A vessel coming out of a side canal is hidden by the corner until the boat is nearly abeam
of it: with a LiDAR, and with any tracker fed by one, it is first seen 10-16 m away, which at
2 m/s is less than the boat needs to stop. A boat that may meet something it cannot yet see
goes at a speed from which it can stop when it does. So before each solve the route ahead is
sampled every `step_m`; at each sample a ray is cast to either side: an *opening* is a side
where the ray runs `depth_m` without meeting a segment (a side canal, a basin's mouth), and it
is *blind* when the line from the boat to the ray's far end crosses a segment (the corner's
wall is in the way). The reference speed is capped so that the boat comes to the first blind
opening at `speed_mps`: v <= sqrt(speed^2 + 2 a (s_open - margin - s)); a boat over the cap
is asked for as much less again, since the NMPC follows a slower reference with a lag, and
the reference brakes along the horizon down to `speed_mps` at the opening less the margin
(`reference_trajectory`'s `slow_to`), as the boat must.

Why it does not slow the boat for nothing: an opening must have a bank running away from the
channel beside it (the side canal's wall), which a stretch of quay the scan missed has not;
only sides within the sensor's range count (beyond it no wall is no evidence); and once the
boat sees into the opening the cap lifts. In a canal narrower than twice `depth_m` every side
ray meets a wall, so straight runs and bends are left alone.
"""

from __future__ import annotations

import math

import numpy as np

from ..geometry import segments_to_endpoints
from ..kernels import pointer
from .path_geometry import geometry_kernel, rays_crossing, rays_crossing_numpy
from .reference import WaypointPath


def blind_opening_ahead(path: WaypointPath, progress_m: float, boat_xy, segments,
                        lookahead_m: float, depth_m: float = 25.0, step_m: float = 2.0,
                        first_m: float = 2.0) -> float | None:
    """Arc length of the first sample ahead (from `progress_m` + `first_m` to `lookahead_m`
    beyond it, every `step_m`) where a side opens at least `depth_m` and the boat cannot
    see into it past the `segments` ((M, 4): x_c, y_c, theta, length), or None. Only sides
    whose far end lies within `lookahead_m` of the boat count: the segments are what a
    sensor of that range reports, and beyond it no wall is no evidence of an opening."""
    segs = np.asarray(segments, float).reshape(-1, 4)
    end = min(progress_m + lookahead_m, path.length)
    if not len(segs) or end <= progress_m + first_m:
        return None
    s = np.arange(progress_m + first_m, end, step_m)
    if not len(s):
        return None
    a, b = segments_to_endpoints(segs)
    boat = np.asarray(boat_xy, float).reshape(2)
    far, open_ = side_rays(path, s, boat, a, b, depth_m, lookahead_m)
    if not open_.any():
        return None
    found = []
    for side in (0, 1):  # starboard, port
        k = np.flatnonzero(open_[side])
        if not len(k):
            continue
        k = k[_banked(s[k], 1.0 - 2.0 * side, path, a, b, step_m)]  # a side canal, not a
        # missed wall
        if not len(k):
            continue
        blind = rays_crossing(boat, far[side, k], a, b)
        if blind.any():
            found.append(float(s[k[np.argmax(blind)]]))
    return min(found) if found else None


def side_rays(path: WaypointPath, s: np.ndarray, boat: np.ndarray, a: np.ndarray,
              b: np.ndarray, depth_m: float, reach_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The rays `depth_m` across the path at arc lengths `s` (n,), to starboard then to port:
    their far ends (2, n, 2), and (2, n) which lie within `reach_m` of the `boat` and meet no
    wall a -> b (through a vertex where two walls meet is no way through). By the compiled
    kernel (`path_geometry.c`), or `side_rays_numpy` where there is none."""
    lib = geometry_kernel()
    if lib is None:
        return side_rays_numpy(path, s, boat, a, b, depth_m, reach_m)
    n = len(s)
    far, open_ = np.empty((2, n, 2)), np.empty((2, n), np.uint8)
    a, b = np.ascontiguousarray(a, float), np.ascontiguousarray(b, float)
    lib.side_rays(n, pointer(np.ascontiguousarray(s, float)), len(path.leg_length),
                  pointer(path.start), pointer(path.delta), pointer(path.leg_length),
                  pointer(path.cumulative), pointer(path.heading), float(depth_m),
                  float(reach_m), float(boat[0]), float(boat[1]), len(a), pointer(a),
                  pointer(b), pointer(far), pointer(open_))
    return far, open_.view(bool)


def side_rays_numpy(path: WaypointPath, s: np.ndarray, boat: np.ndarray, a: np.ndarray,
                    b: np.ndarray, depth_m: float, reach_m: float) -> tuple[np.ndarray, np.ndarray]:
    """`side_rays`' numpy twin."""
    xy, psi = path.at(s)
    normal = np.column_stack([-np.sin(psi), np.cos(psi)])  # to starboard of the path
    far = np.stack([xy + side * depth_m * normal for side in (1.0, -1.0)])
    seen = np.hypot(far[..., 0] - boat[0], far[..., 1] - boat[1]) <= reach_m
    open_ = ~np.stack([rays_crossing_numpy(xy, f, a, b, closed=True) for f in far])
    return far, seen & open_


def _banked(s_open: np.ndarray, side: float, path: WaypointPath, a, b, step_m: float,
            min_angle_deg: float = 45.0, reach_m: float = 6.0) -> np.ndarray:
    """Which open samples (arc lengths `s_open` on `side`) lie within `reach_m` along the
    path of a wall running away from the channel on that side (more than `min_angle_deg`
    across the path, wholly on that side): the bank of a side canal. A quay the scan missed
    for a while leaves a gap with no such wall, so it is not taken for an opening."""
    window = (max(float(s_open.min()) - 40.0, 0.0), float(s_open.max()) + 40.0)
    s_a, d_a = path.frame(a, *window)
    s_b, d_b = path.frame(b, *window)
    _, h = path.at(0.5 * (s_a + s_b))
    u = b - a
    along = np.abs(u[:, 0] * np.cos(h) + u[:, 1] * np.sin(h)) / np.maximum(
        np.hypot(u[:, 0], u[:, 1]), 1e-9)
    bank = (along < math.cos(math.radians(min_angle_deg))) & (d_a * side > 0) & (d_b * side > 0)
    if not bank.any():
        return np.zeros(len(s_open), bool)
    lo = np.minimum(s_a, s_b)[bank] - reach_m - step_m
    hi = np.maximum(s_a, s_b)[bank] + reach_m + step_m
    return ((s_open[:, None] >= lo[None]) & (s_open[:, None] <= hi[None])).any(axis=1)


def blind_speed_cap(distance_m: float, speed_mps: float, decel_mps2: float) -> float:
    """The highest speed from which braking at `decel_mps2` comes down to `speed_mps` within
    `distance_m` (`speed_mps` itself once the distance is used up)."""
    return math.sqrt(speed_mps * speed_mps + 2.0 * decel_mps2 * max(distance_m, 0.0))


def ask_below_cap(cap_mps: float, boat_speed_mps: float) -> float:
    """The speed to ask of a boat going at `boat_speed_mps` under a cap: the cap, or with the
    boat above it as much less again (down to half the cap). The NMPC follows a slower
    reference with a lag (a fuzz case came to a blind side canal at 1.5 m/s for a cap of
    1.0 and met the vessel coming out at 0.05 m), so a boat over the cap is asked to brake
    the harder, and is at the cap by the opening."""
    if boat_speed_mps <= cap_mps:
        return cap_mps
    return max(2.0 * cap_mps - boat_speed_mps, 0.5 * cap_mps)
