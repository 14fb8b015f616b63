"""Metrics on hand-checked cases."""

import numpy as np
import pytest

from controller.geometry import Polyline
from scenarios import metrics


def test_hull_circles_sit_fore_and_aft_along_the_heading():
    c = metrics.hull_circle_centres([[10.0, 5.0, np.pi / 2]])
    assert c[0, 0] == pytest.approx([10.0, 7.0])  # bow: heading east
    assert c[0, 1] == pytest.approx([10.0, 3.0])


def test_clearance_to_two_walls():
    walls = [np.array([[-100, -6.0], [100, -6.0]]), np.array([[-100, 4.0], [100, 4.0]])]
    # heading north along the canal at y = 1: 7 m to the west wall, 3 m to the east wall
    d = metrics.clearance([[0, 1.0, 0.0]], walls)
    assert d == pytest.approx(np.array([[3.0, 3.0]]))
    # turned east: the bow circle is 1 m from the east wall, the stern 5 m from the west wall
    d = metrics.clearance([[0, 1.0, np.pi / 2]], walls)
    assert d == pytest.approx(np.array([[1.0, 5.0]]))


def test_time_below_counts_steps():
    assert metrics.time_below([5, 4.9, 3, 7, 6.99], 7.0, 0.1) == pytest.approx(0.4)


def test_control_effort_of_known_rates():
    cmds = np.array([[1.0, 0.0], [2.0, 4.0], [2.0, 4.0]])
    rates = metrics.command_rates(cmds, 0.1)
    assert rates == pytest.approx(np.array([[10, 0], [10, 40], [0, 0]]))
    assert metrics.control_effort(rates) == pytest.approx(100 + 100 + 1600)
    assert metrics.control_effort(rates, (1e-4, 1e-4)) == pytest.approx(0.18)


def test_cross_track_to_a_path():
    path = Polyline([[0, 0], [100, 0]])
    assert metrics.cross_track([[10, 2], [50, -3]], path) == pytest.approx([2, 3])


def test_timing_stats():
    s = metrics.TimingStats.of([0.001] * 99 + [0.01])
    assert s.max_ms == pytest.approx(10.0) and s.mean_ms == pytest.approx(1.09)


def test_hull_contact_sees_a_wall_inside_the_hull_rectangle():
    walls = [np.array([[-100, -6.0], [100, -6.0]]), np.array([[-100, 4.0], [100, 4.0]])]
    contact = metrics.HullContact(walls)  # 7.9 m x 2.6 m
    assert not contact.touches([0.0, 2.6, 0.0])  # side 0.1 m from the east wall
    assert contact.touches([0.0, 2.8, 0.0])  # side 0.1 m across it
    assert not contact.touches([0.0, 0.0, np.pi / 2])  # across the canal: bow 0.05 m short
    assert contact.touches([0.0, 0.1, np.pi / 2])
    # a pier end poking into the hull from the side crosses no hull edge only if inside it
    pier = [np.array([[0.5, 0.5], [0.5, 20.0]])]
    assert metrics.HullContact(pier).touches([0.0, 0.0, 0.0])
    assert not metrics.HullContact(pier).touches([0.0, -2.0, 0.0])
