"""Line-of-sight guidance: Fossen's lookahead-based steering law.

For a path leg from p_k to p_k+1 with direction pi_p (from north, clockwise), the
cross-track error is y_e = -(x - x_k) sin pi_p + (y - y_k) cos pi_p (positive to the right
of the path, looking along it), and the desired course is chi_d = pi_p + atan(-y_e / Delta)
with the lookahead distance Delta. The desired heading corrects the course by the crab
angle beta = atan2(v, u) that a current or a turn adds: psi_d = chi_d - beta.
(T. I. Fossen, Handbook of Marine Craft Hydrodynamics and Motion Control, 2021, ch. 12.)
"""

from __future__ import annotations

import numpy as np

from ..geometry import wrap_angle


def cross_track_error(position, leg_start, leg_heading: float) -> float:
    """y_e of a position relative to a path leg (m, positive right of the path)."""
    dx, dy = np.asarray(position, float)[:2] - np.asarray(leg_start, float)[:2]
    return float(-dx * np.sin(leg_heading) + dy * np.cos(leg_heading))


def los_course(position, leg_start, leg_heading: float, lookahead_m: float) -> float:
    """Desired course chi_d (rad) that steers onto the leg within about a lookahead."""
    if lookahead_m <= 0:
        raise ValueError(f"LOS lookahead must be positive, got {lookahead_m}")
    y_e = cross_track_error(position, leg_start, leg_heading)
    return float(wrap_angle(leg_heading + np.arctan(-y_e / lookahead_m)))


def heading_from_course(course: float, u: float, v: float) -> float:
    """Heading that gives `course` over ground when the boat crabs by atan2(v, u)."""
    if u < 0.2:  # at low speed the crab angle is noise: steer the course directly
        return float(course)
    return float(wrap_angle(course - np.arctan2(v, u)))


def lookahead_course(position, path, s_m: float, lookahead_m: float) -> float:
    """Course toward the point `lookahead_m` further along `path` (a geometry.Polyline) than
    the boat's projection at arc length `s_m`.

    On a straight leg this is exactly Fossen's law, pi_p + atan(-y_e / Delta); on a path of
    short legs (a planner's trajectory) it also sees the curve ahead, where the current leg's
    direction alone would not.
    """
    if lookahead_m <= 0:
        raise ValueError(f"LOS lookahead must be positive, got {lookahead_m}")
    target = path.at(s_m + lookahead_m)[0][0]
    if s_m + lookahead_m > path.length:  # past the end: continue along the last leg
        target = target + (s_m + lookahead_m - path.length) * np.array(
            [np.cos(path.headings[-1]), np.sin(path.headings[-1])])
    d = target - np.asarray(position, float)[:2]
    return float(np.arctan2(d[1], d[0]))
