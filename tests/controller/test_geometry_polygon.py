"""Polygon helpers of controller.geometry: area, point in polygon, touching segments."""

import numpy as np
import pytest

from controller.geometry import (point_segment_distance, points_in_polygon, polygon_area,
                                 polyline_self_touch, segments_cross,
                                 segments_touch, self_intersection)

SQUARE = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])


def test_polygon_area_is_signed_and_zero_for_collinear_points():
    assert polygon_area(SQUARE) == pytest.approx(100.0)  # north, then east: clockwise on a map
    assert polygon_area(SQUARE[::-1]) == pytest.approx(-100.0)
    assert polygon_area([[0, 0], [1, 1], [3, 3]]) == pytest.approx(0.0, abs=1e-12)
    assert polygon_area([[0, 0], [4, 0], [0, 3]]) == pytest.approx(6.0)


def test_points_on_the_boundary_or_outside_are_not_inside():
    pts = [[5, 5], [0.001, 5], [0, 5], [10, 10], [5, 10], [11, 5], [-3, -3], [5, 10.5]]
    assert points_in_polygon(pts, SQUARE).tolist() == [True, True, False, False, False, False,
                                                        False, False]


def test_points_in_a_non_convex_polygon():
    u_shape = np.array([[0, 0], [10, 0], [10, 3], [2, 3], [2, 7], [10, 7], [10, 10], [0, 10]], float)
    inside = points_in_polygon([[1, 5], [5, 5], [5, 1.5], [5, 8.5], [2, 5]], u_shape)
    assert inside.tolist() == [True, False, True, True, False]


def test_boundary_margin_widens_the_outside():
    assert points_in_polygon([[5, 0.5]], SQUARE, boundary_m=1.0).tolist() == [False]
    assert points_in_polygon([[5, 1.5]], SQUARE, boundary_m=1.0).tolist() == [True]


def test_segments_touch_counts_vertices_and_overlaps_that_a_crossing_misses():
    wall_a, wall_b = np.array([[0.0, 8.0], [2.0, 8.0]]), np.array([[2.0, 8.0], [4.0, 8.0]])
    a1, b1 = np.array([[2.0, 0.0]]), np.array([[2.0, 20.0]])  # through the shared vertex
    assert not segments_cross(a1, b1, np.vstack([wall_a[:1], wall_b[:1]]),
                              np.vstack([wall_a[1:], wall_b[1:]])).any()
    touch = segments_touch(a1, b1, np.vstack([wall_a[:1], wall_b[:1]]),
                           np.vstack([wall_a[1:], wall_b[1:]]))
    assert touch.shape == (1, 2) and touch.all()
    # an end on the other segment, a collinear overlap, and two segments apart
    assert segments_touch([[0, 0]], [[1, 8]], [[0, 8]], [[2, 8]]).tolist() == [[True]]
    assert segments_touch([[1, 8]], [[3, 8]], [[0, 8]], [[2, 8]]).tolist() == [[True]]
    assert segments_touch([[0, 0]], [[1, 7.9]], [[0, 8]], [[2, 8]]).tolist() == [[False]]


def test_polyline_self_touch_finds_a_loop_through_a_vertex():
    # the fourth leg ends on the first leg's end vertex: no proper crossing, but a loop
    loop = [[0, 0], [10, 0], [10, 10], [20, 10], [10, 0]]
    assert polyline_self_touch(loop) is not None
    through = [[0, 0], [10, 0], [20, 0], [20, 10], [10, 10], [10, -10]]  # through vertex (10, 0)
    assert self_intersection(through) is None
    assert polyline_self_touch(through) == (0, 4)
    assert polyline_self_touch([[0, 0], [10, 0], [10, 10], [0, 10]]) is None
    square = [[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]]
    assert polyline_self_touch(square, closed=True) is None
    assert polyline_self_touch(square) == (0, 3)


def test_segments_touch_pruned_by_boxes_equals_every_pair_tested():
    """`segments_touch` tests only pairs whose boxes overlap; its reference tests every pair
    (crossings, and each end against the other segment), on grid points where ends sit on
    other segments, collinear overlaps and shared vertices abound."""
    def every_pair(a1, b1, a2, b2, tol):
        touch = segments_cross(a1, b1, a2, b2)
        touch |= point_segment_distance(a1, a2, b2) <= tol
        touch |= point_segment_distance(b1, a2, b2) <= tol
        touch |= (point_segment_distance(a2, a1, b1) <= tol).T
        touch |= (point_segment_distance(b2, a1, b1) <= tol).T
        return touch

    rng = np.random.default_rng(3)
    hits = 0
    for k in range(200):
        n, m = rng.integers(1, 30, 2)
        grid = k % 2 == 0
        a1, b1 = (rng.integers(0, 6, (n, 2)).astype(float) if grid
                  else rng.normal(size=(n, 2)) * 3 for _ in range(2))
        a2, b2 = (rng.integers(0, 6, (m, 2)).astype(float) for _ in range(2))
        tol = (1e-9, 0.05, 0.5)[k % 3]
        touch = segments_touch(a1, b1, a2, b2, tol)
        assert np.array_equal(touch, every_pair(a1, b1, a2, b2, tol)), k
        hits += int(touch.sum())
    assert hits > 1000
