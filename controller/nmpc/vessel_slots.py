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
                    max_inflation_m: float = 6.0) -> VesselSelection:
    """Fill `n_slots` vessel slots from `tracks` (objects with `id`, `position`, `velocity`,
    `heading_rad`, `length_m`, `width_m` and a 4x4 `covariance` of [x, y, vx, vy]).

    `plan`: the boat's planned positions at stages 0..Np, (Np + 1, 2) (None: `position`
    held); vessels farther than `range_m` from the plan at every stage are left out.
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
    gap = predicted - boat
    closest = np.hypot(gap[..., 0], gap[..., 1]).min(axis=1) - 0.5 * lengths
    order = np.argsort(closest, kind="stable")
    order = order[closest[order] <= range_m]
    chosen = order[:n_slots]
    k = len(chosen)
    if k:
        cov = np.array([np.asarray(tracks[i].covariance, float).reshape(4, 4) for i in chosen])
        var_p = 0.5 * np.maximum(cov[:, 0, 0] + cov[:, 1, 1], 0.0)
        var_v = 0.5 * np.maximum(cov[:, 2, 2] + cov[:, 3, 3], 0.0)
        grow = np.minimum(2 * sigma * np.sqrt(var_p[:, None] + var_v[:, None] * t * t),
                          max_inflation_m).T  # (horizon, k)
        slots[:, :k, 0:2] = predicted[chosen].transpose(1, 0, 2)
        slots[:, :k, 2] = [float(tracks[i].heading_rad) for i in chosen]
        slots[:, :k, 3] = lengths[chosen] + grow
        slots[:, :k, 4] = np.array([float(tracks[i].width_m) for i in chosen]) + grow
        slots[:, :k, 5] = 1.0
    return VesselSelection(slots, tuple(tracks[i].id for i in chosen), len(order) - k,
                           closest[chosen])


def vessel_slot_margin(px, py, slot, margin):
    """Numeric super-ellipse margin of a circle centre against one vessel slot row (for
    tests and plots); `margin` is R_b + d_v + s."""
    from .obstacle import super_ellipse_margin

    x, y, theta, length, width, active = slot
    if not active:
        return 1.0
    return float(super_ellipse_margin(px, py, x, y, theta, length, margin,
                                      width / 2 + margin))

