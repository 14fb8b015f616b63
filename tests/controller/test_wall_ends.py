"""A face running from a wall's end into the land behind it is wall, not a boat
(`clusters.behind_a_wall_end`): the far side of a side canal seen through its mouth."""

import math

import numpy as np

from controller.perception.clusters import behind_a_wall_end

# The main canal's north quay along y = 10 from x = 40 to x = 140 (x_c, y_c, theta, length);
# the boat's LiDAR at the canal's middle.
QUAY = np.array([[90.0, 10.0, 0.0, 100.0]])
SENSOR = (100.0, 0.0)


def face(x0, y0, x1, y1, n=12):
    t = np.linspace(0.0, 1.0, n)[:, None]
    pts = np.array([x0, y0]) + t * np.array([x1 - x0, y1 - y0])
    axis = np.array([x1 - x0, y1 - y0]) / math.hypot(x1 - x0, y1 - y0)
    return pts, axis


def test_the_side_canals_corner_face_running_inland_is_wall():
    pts, axis = face(140.0, 10.3, 140.0, 14.0)  # the quay's end, then north into the land
    assert behind_a_wall_end(pts, axis, SENSOR, QUAY)


def test_a_boat_moored_alongside_the_quay_is_not():
    pts, axis = face(100.0, 9.0, 109.0, 9.0)
    assert not behind_a_wall_end(pts, axis, SENSOR, QUAY)


def test_a_boat_moored_bow_on_lies_on_the_waters_side():
    pts, axis = face(120.0, 9.5, 120.0, 4.0)  # touches the quay, runs into the canal
    assert not behind_a_wall_end(pts, axis, SENSOR, QUAY)


def test_a_face_far_from_any_wall_end_is_not():
    pts, axis = face(170.0, 10.5, 170.0, 14.0)  # 30 m beyond the quay's end
    assert not behind_a_wall_end(pts, axis, SENSOR, QUAY)
    assert not behind_a_wall_end(pts, axis, SENSOR, np.zeros((0, 4)))
