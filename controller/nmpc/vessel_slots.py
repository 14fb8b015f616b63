"""The NMPC's vessel slots: other vessels, each predicted at every stage of the horizon.

Like the segment slots, a fixed number (4 by default) so the problem is built once: each slot
is, per stage k = 1..Np, the vessel's predicted pose (constant velocity from its track, t_k =
k Ts ahead) and its hull inflated by the track's uncertainty grown to that time (2 sigma each
side, at most `max_inflation_m`). Four because a canal scene within the horizon's 50 m rarely
holds more than two or three boats (meeting one while overtaking another), and each slot adds
2 x Np rows to every QP (4 slots: 200 rows beside the segments' 800). Vessels are ranked by
how close they come to the planned path at the same stage (the warm start; the boat itself
at a cold start), so the one that matters most always has a slot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

VESSEL_FIELDS = ("x", "y", "theta", "length", "width", "active")


@dataclass(frozen=True)
class VesselSelection:
    """The slots handed to the OCP, which tracks fill them, and what did not fit."""

    slots: np.ndarray  # (Np, n_slots, 6) rows (x, y, theta, length, width, active) per stage
    ids: tuple  # the track id in each filled slot, in slot order
    dropped: int  # vessels in range left out for want of a slot
    closest_m: np.ndarray  # (n_filled,) least predicted distance to the plan of each


def predict_vessels(tracks, n_slots: int, horizon: int, step_s: float, plan=None,
                    position=None, range_m: float = 60.0, sigma: float = 2.0,
                    max_inflation_m: float = 6.0,
                    max_lateral_inflation_m: float | None = None,
                    path=None, path_window=None, lanes=frozenset()) -> VesselSelection:
    """Fill `n_slots` vessel slots from `tracks` (objects with `id`, `position`, `velocity`,
    `heading_rad`, `length_m`, `width_m` and a 4x4 `covariance` of [x, y, vx, vy]).

    `plan`: the boat's planned positions at stages 0..Np, (Np + 1, 2) (None: `position`
    held); vessels farther than `range_m` from the plan at every stage are left out.
    The hull grows along its heading by the uncertainty along it (at most `max_inflation_m`)
    and across by the uncertainty across (at most `max_lateral_inflation_m`, default the
    same): a vessel in a canal keeps to its side of the channel, so over a long horizon its
    place along the channel is what grows uncertain, not its side; a width grown as much as
    the length would fill a narrow canal and leave a boat meeting it nothing to do but go
    astern until the vessel's predicted hull no longer reaches it within the horizon.

    `path` (a `reference.WaypointPath`: the boat's route, which follows the canal) and
    `path_window` (s_min, s_max): a vessel beside the route and moving along it is predicted
    along the route (`along_path`), round its bends, not straight on through the quay: a
    boat meeting one at a bend otherwise sees it coming across the canal at it.

    `lanes`: ids of vessels met head-on (`seamanship`: coming the other way on their side of
    the channel). Such a vessel's hull is placed, at every stage, abeam of the boat's planned
    place on the vessel's side of the channel (no nearer than where it is now): its lane,
    from it down the channel past the boat, counts as taken for the whole horizon. With its
    hull moving down the channel instead, a canal too narrow for both separations leaves
    the plan one way to keep them within the horizon: astern, away from the vessel at its
    own speed (seen at 1.3 m/s for 60 m); with the lane, going astern gains nothing and the
    boat keeps to its own side and passes.
    """
    slots = np.zeros((horizon, n_slots, len(VESSEL_FIELDS)))
    tracks = list(tracks or ())
    if not tracks or n_slots == 0:
        return VesselSelection(slots, (), 0, np.zeros(0))
    t = step_s * np.arange(1, horizon + 1)  # stages 1..Np
    if plan is not None:
        boat = np.asarray(plan, float).reshape(-1, 2)[1:horizon + 1]
    else:
        boat = np.tile(np.asarray(position, float).reshape(-1)[:2], (horizon, 1))
    # every track at once, as arrays (n_tracks, ...): no loop over tracks or stages
    positions = np.array([np.asarray(tr.position, float).reshape(2) for tr in tracks])
    velocities = np.array([np.asarray(tr.velocity, float).reshape(2) for tr in tracks])
    lengths = np.array([float(tr.length_m) for tr in tracks])
    predicted = positions[:, None, :] + t[None, :, None] * velocities[:, None, :]
    headings = np.tile(np.array([float(tr.heading_rad) for tr in tracks])[:, None],
                       (1, horizon))
    if path is not None:
        on = along_path(path, path_window, positions, velocities, t, predicted, headings)
        lane = [i for i in np.flatnonzero(on).tolist() if tracks[i].id in lanes]
        if lane:
            _in_lane(path, path_window, positions[lane], boat, predicted, headings, lane)
    gap = predicted - boat
    closest = np.hypot(gap[..., 0], gap[..., 1]).min(axis=1) - 0.5 * lengths
    order = np.argsort(closest, kind="stable")
    order = order[closest[order] <= range_m]
    chosen = order[:n_slots]
    k = len(chosen)
    if k:
        cov = np.array([np.asarray(tracks[i].covariance, float).reshape(4, 4) for i in chosen])
        heading = headings[chosen, 0]
        along = np.column_stack([np.cos(heading), np.sin(heading)])  # (k, 2)
        across = np.column_stack([-along[:, 1], along[:, 0]])

        def var(block, axis):  # variance along each vessel's axis, from a 2x2 block
            return np.maximum(np.einsum("ki,kij,kj->k", axis, block, axis), 0.0)

        lateral_cap = max_inflation_m if max_lateral_inflation_m is None \
            else max_lateral_inflation_m
        grow_len = np.minimum(2 * sigma * np.sqrt(
            var(cov[:, :2, :2], along)[:, None] + var(cov[:, 2:, 2:], along)[:, None] * t * t),
            max_inflation_m).T  # (horizon, k)
        grow_wid = np.minimum(2 * sigma * np.sqrt(
            var(cov[:, :2, :2], across)[:, None] + var(cov[:, 2:, 2:], across)[:, None] * t * t),
            lateral_cap).T
        slots[:, :k, 0:2] = predicted[chosen].transpose(1, 0, 2)
        slots[:, :k, 2] = headings[chosen].T
        slots[:, :k, 3] = lengths[chosen] + grow_len
        slots[:, :k, 4] = np.array([float(tracks[i].width_m) for i in chosen]) + grow_wid
        slots[:, :k, 5] = 1.0
    return VesselSelection(slots, tuple(tracks[i].id for i in chosen), len(order) - k,
                           closest[chosen])


ALONG_MIN_MPS = 0.3  # slower along the route than this: not following the canal
PATH_REACH_M = 25.0  # farther from the route than this: in another channel
DRIFT_TAU_S = 3.0  # a vessel's speed across the route dies out with this time constant


def along_path(path, window, positions, velocities, t, predicted, headings) -> np.ndarray:
    """Predict, in place, the vessels that follow the canal along the route `path`: their
    place along it advances at their speed along it, their offset from it drifts by their
    speed across it, dying out with `DRIFT_TAU_S` (a boat settles on its side of the
    channel), their heading turns with the route's legs. Vessels off the route's span,
    farther than `PATH_REACH_M` from it, or moving more across it than along (crossing,
    drifting) keep their straight-line prediction. Returns which vessels were moved."""
    s_min, s_max = (0.0, None) if window is None else window
    s, d = path.frame(positions, max(s_min, 0.0), s_max)
    xy, h = path.at(s)
    u = np.column_stack([np.cos(h), np.sin(h)])
    n = np.column_stack([-u[:, 1], u[:, 0]])
    rel = positions - xy
    along = np.einsum("ij,ij->i", velocities, u)
    across = np.einsum("ij,ij->i", velocities, n)
    on = ((np.abs(np.einsum("ij,ij->i", rel, u)) < 1.0) & (np.abs(d) <= PATH_REACH_M)
          & (np.abs(along) >= ALONG_MIN_MPS) & (np.abs(along) >= np.abs(across)))
    for i in np.flatnonzero(on).tolist():
        s_k = s[i] + along[i] * t
        d_k = d[i] + across[i] * DRIFT_TAU_S * (1.0 - np.exp(-t / DRIFT_TAU_S))
        end = np.clip(s_k, 0.0, path.length)
        xy_k, h_k = path.at(end)
        beyond = s_k - end  # past either end of the route: straight on along the end leg
        c, sn = np.cos(h_k), np.sin(h_k)
        predicted[i, :, 0] = xy_k[:, 0] + beyond * c - d_k * sn
        predicted[i, :, 1] = xy_k[:, 1] + beyond * sn + d_k * c
        headings[i] = h_k if along[i] > 0 else h_k + np.pi
    return on


def _in_lane(path, window, positions, boat, predicted, headings, rows) -> None:
    """Vessels `rows` (at `positions`) met head-on, placed at every stage in their own lane
    (at the vessel's offset): where the vessel is predicted while that is still ahead of
    the boat's planned place (`boat`, (Np, 2)), abeam of it from when they would have met,
    and never beyond where the vessel is now. So the lane is taken from where the vessel
    will be: a boat in it when a vessel comes into view far ahead has the time to move
    over (abeam of the boat from the first stage, it had to be out of the lane at once)."""
    s_min, s_max = (0.0, None) if window is None else window
    s_v, d_v = path.frame(positions, max(s_min, 0.0), s_max)
    s_b, _ = path.frame(boat, max(s_min, 0.0), s_max)
    for k, i in enumerate(rows):
        s_pred, _ = path.frame(predicted[i], max(s_min, 0.0), s_max)
        s_k = np.minimum(np.maximum(s_b, s_pred), s_v[k])
        xy, h = path.at(s_k)
        predicted[i, :, 0] = xy[:, 0] - d_v[k] * np.sin(h)
        predicted[i, :, 1] = xy[:, 1] + d_v[k] * np.cos(h)
        headings[i] = h + np.pi


def vessel_slot_margin(px, py, slot, margin):
    """Numeric super-ellipse margin of a circle centre against one vessel slot row (for
    tests and plots); `margin` is R_b + d_v + s."""
    from .obstacle import super_ellipse_margin

    x, y, theta, length, width, active = slot
    if not active:
        return 1.0
    return float(super_ellipse_margin(px, py, x, y, theta, length, margin,
                                      width / 2 + margin))



REST_MPS = 0.15  # a vessel not moving is at rest below this speed (a track's noise above)


def at_rest(tracks) -> tuple:
    """The vessels among `tracks` lying at rest: known for vessels (a kayak stopped, a boat
    waiting; `Track.vessel`), not moving, and slower than `REST_MPS` (a slow barge whose
    track reads below the moving test a while is not stopping)."""
    return tuple(tr for tr in tracks if not getattr(tr, "moving", True)
                 and getattr(tr, "vessel", False)
                 and float(np.hypot(*np.asarray(tr.velocity, float).reshape(2))) < REST_MPS)


def rest_outlines(tracks, grow_m: float, circles=None, radius_m: float = 0.0) -> np.ndarray:
    """The outlines of vessels at rest, each side moved out by `grow_m`, as (4 K, 4)
    segments (x_c, y_c, theta, length): walls the hull circles keep d_p from, slack and
    all, so the hulls keep `grow_m` plus the circles' reach past the hull. Never grown over
    the boat's hull circles (`circles` (n, 2), `radius_m`): a vessel that stops (or whose
    track stops a moment) beside the boat must not put a wall on it."""
    rows = []
    for tr in tracks:
        x, y = np.asarray(tr.position, float).reshape(2)
        c, s = np.cos(tr.heading_rad), np.sin(tr.heading_rad)
        half_l, half_w = 0.5 * float(tr.length_m), 0.5 * float(tr.width_m)
        grow = grow_m
        if circles is not None:  # the circles' least distance to the outline, less R_b
            rel = np.asarray(circles, float).reshape(-1, 2) - (x, y)
            out_l = np.maximum(np.abs(rel @ (c, s)) - half_l, 0.0)
            out_w = np.maximum(np.abs(rel @ (-s, c)) - half_w, 0.0)
            grow = min(grow_m, max(float(np.hypot(out_l, out_w).min()) - radius_m, 0.0))
        half_l, half_w = half_l + grow, half_w + grow
        for along, across, theta, length in ((half_l, 0.0, tr.heading_rad + np.pi / 2,
                                              2 * half_w),
                                             (-half_l, 0.0, tr.heading_rad + np.pi / 2,
                                              2 * half_w),
                                             (0.0, half_w, tr.heading_rad, 2 * half_l),
                                             (0.0, -half_w, tr.heading_rad, 2 * half_l)):
            rows.append((x + along * c - across * s, y + along * s + across * c, theta,
                         length))
    return np.array(rows, float).reshape(-1, 4)
