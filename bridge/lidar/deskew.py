"""De-skewing a sweep for the boat's motion: each point moved from where the body was when
it was measured to the body at one reference time, with the navigation state's velocities
(u, v, r held over the sweep: a constant twist, integrated exactly in the plane)."""

from __future__ import annotations

import numpy as np


def deskew(points_body: np.ndarray, times_s: np.ndarray, ref_time_s: float, velocity) -> np.ndarray:
    """Body-frame points (N, 3) measured at `times_s` -> the body frame at `ref_time_s`,
    for body velocities `velocity` = (u m/s, v m/s, r rad/s; r > 0 turns to starboard)."""
    u, v, r = (float(x) for x in velocity)
    dt = np.asarray(times_s, float) - float(ref_time_s)
    a = r * dt
    if abs(r) > 1e-9:
        s_, c_ = np.sin(a) / r, (1.0 - np.cos(a)) / r
    else:
        s_, c_ = dt, 0.5 * r * dt * dt
    # where the body was at each point's time, in the reference body frame
    px, py = u * s_ - v * c_, u * c_ + v * s_
    ca, sa = np.cos(a), np.sin(a)
    p = np.asarray(points_body, float)
    out = np.empty_like(p)
    out[:, 0] = ca * p[:, 0] - sa * p[:, 1] + px
    out[:, 1] = sa * p[:, 0] + ca * p[:, 1] + py
    out[:, 2] = p[:, 2]
    return out
