"""The obstacle-avoidance constraint of the paper (eq. mpc:pnorm), written once.

A circle centre (px, py) keeps clear of a segment L = (x_c, y_c, theta, length) when it lies
outside the power-4 super-ellipse around the segment with half axes `length/2 + margin_along`
along the segment and `margin_across` across it. We use the 4th root of the paper's
expression, (X^4 + Y^4)^(1/4) - 1 >= 0: the same set, but it grows like a distance, so its
linearisation stays accurate far from a wall and the problem is well scaled. Works on
numbers and on CasADi expressions alike.
"""

from __future__ import annotations

import casadi as ca


def super_ellipse_margin(px, py, x_c, y_c, theta, length, margin_along, margin_across):
    """h = (X^4 + Y^4)^(1/4) - 1: >= 0 outside the super-ellipse around the segment."""
    dx, dy = px - x_c, py - y_c
    c, s = ca.cos(theta), ca.sin(theta)
    X = (dx * c + dy * s) / (length / 2 + margin_along)
    Y = (-dx * s + dy * c) / margin_across
    return (X**4 + Y**4 + 1e-12) ** 0.25 - 1


def hull_circle_centres(x, y, psi, offsets):
    """Centres of the hull circles at `offsets` (m) along the body x axis."""
    c, s = ca.cos(psi), ca.sin(psi)
    return [(x + d * c, y + d * s) for d in offsets]
