"""A built-in demo canal (about 420 m): bends, width changes, a pier, a moored boat, a bridge.

It serves `canalnav detect` and the detection benchmark until scenario files exist, and it is
built from the same public constructors a scenario file will use.
"""

from __future__ import annotations

import numpy as np

from controller.geometry import offset_polyline

from .canal import CanalWorld, Obstacle, Wall

# (kind, value, radius_m): "straight" value = length in m, "turn" value = angle in degrees,
# positive to starboard (clockwise, as headings).
LEGS = (
    ("straight", 70.0, 0.0),
    ("turn", 50.0, 60.0),
    ("straight", 60.0, 0.0),
    ("turn", -80.0, 45.0),
    ("straight", 50.0, 0.0),
    ("turn", 35.0, 80.0),
    ("straight", 70.0, 0.0),
)
WIDTH_PROFILE = ((0.0, 16.0), (110.0, 16.0), (150.0, 12.0), (215.0, 12.0), (245.0, 20.0),
                 (330.0, 20.0), (360.0, 15.0))


def centre_line(step_m: float = 2.0, start=(0.0, 0.0), heading_rad: float = 0.0) -> np.ndarray:
    """The demo canal's centre line sampled about every `step_m` metres."""
    pts = [np.asarray(start, float)]
    h = heading_rad
    for kind, value, radius in LEGS:
        if kind == "straight":
            n = max(int(np.ceil(value / step_m)), 1)
            for _ in range(n):
                pts.append(pts[-1] + value / n * np.array([np.cos(h), np.sin(h)]))
        else:
            turn = np.radians(value)
            n = max(int(np.ceil(abs(turn) * radius / step_m)), 1)
            for _ in range(n):
                dh = turn / n
                chord = 2.0 * radius * np.sin(abs(dh) / 2.0)
                mid = h + dh / 2.0
                pts.append(pts[-1] + chord * np.array([np.cos(mid), np.sin(mid)]))
                h += dh
    return np.array(pts)


def _rectangle(centre, heading, length, width) -> np.ndarray:
    c, s = np.cos(heading), np.sin(heading)
    along, across = np.array([c, s]), np.array([-s, c])
    corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    return np.array([centre + i * length / 2 * along + j * width / 2 * across for i, j in corners])


def demo_canal() -> CanalWorld:
    """The demo canal: two banks of varying height and backdrop, a pier, a boat, a bridge."""
    centre = centre_line()
    from controller.geometry import Polyline

    line = Polyline(centre)
    s = line.cumulative
    width = np.interp(s, *np.array(WIDTH_PROFILE).T)
    left = offset_polyline(centre, -width / 2.0)
    right = offset_polyline(centre, width / 2.0)

    def piece(points, s0, s1):
        # Consecutive pieces share their boundary vertex, so the bank has no gap.
        i0, i1 = np.searchsorted(s, s0), np.searchsorted(s, s1)
        return points[i0:i1 + 1]

    # The banks change character along the canal: quay heights 1.2-2.5 m, buildings or trees.
    walls = (
        Wall(piece(left, 0, 150), 1.8, "left", 4.0, 12.0, "left-town"),
        Wall(piece(left, 150, 300), 1.2, "left", 6.0, 6.0, "left-park"),
        Wall(piece(left, 300, 1e9), 2.5, "left", 3.0, 15.0, "left-harbour"),
        Wall(piece(right, 0, 200), 1.5, "right", 5.0, 9.0, "right-town"),
        Wall(piece(right, 200, 1e9), 2.0, "right", 8.0, 0.0, "right-promenade"),
    )

    obstacles = []
    # A short pier sticking 3 m out from the left wall.
    xy, h = line.at(95.0)
    w95 = float(np.interp(95.0, *np.array(WIDTH_PROFILE).T))
    normal = np.array([-np.sin(h[0]), np.cos(h[0])])
    pier_centre = xy[0] - normal * (w95 / 2.0 - 1.25)  # 3 m into the water, 0.5 m into the wall
    obstacles.append(Obstacle(_rectangle(pier_centre, h[0] + np.pi / 2, 3.5, 2.0), 1.0, 0.0,
                              "pier", "pier"))
    # A moored boat along the right wall in the wide stretch.
    xy, h = line.at(290.0)
    normal = np.array([-np.sin(h[0]), np.cos(h[0])])
    boat_centre = xy[0] + normal * (20.0 / 2.0 - 1.6)
    obstacles.append(Obstacle(_rectangle(boat_centre, h[0], 8.0, 2.6), 1.3, 0.0,
                              "boat", "moored-boat"))
    # A footbridge across the canal (deck 3.2-3.8 m above water): the boat passes under it.
    xy, h = line.at(185.0)
    obstacles.append(Obstacle(_rectangle(xy[0], h[0], 4.0, 30.0), 3.8, 3.2,
                              "bridge", "footbridge"))
    return CanalWorld(walls, tuple(obstacles), centre, "demo")
