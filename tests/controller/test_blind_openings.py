"""Safe speed past a blind opening (`controller.nmpc.blind_openings`, Rules 6 and 9(f))."""

import math

import numpy as np
import pytest

from controller.nmpc.blind_openings import (ask_below_cap, blind_opening_ahead,
                                             blind_speed_cap)
from controller.nmpc.reference import waypoint_path

PATH = waypoint_path([[0.0, 0.0], [300.0, 0.0]])


def seg(a, b):
    (x0, y0), (x1, y1) = a, b
    return [0.5 * (x0 + x1), 0.5 * (y0 + y1), math.atan2(y1 - y0, x1 - x0),
            math.hypot(x1 - x0, y1 - y0)]


def walls(side_canal=True, port_wall=True):
    """A 20 m canal along x; a side canal 140-156 m crossing it (both sides)."""
    rows = [seg((0, 10), (140, 10)), seg((156, 10), (300, 10))]
    if port_wall:
        rows += [seg((0, -10), (140, -10))]
    rows += [seg((156, -10), (300, -10))]
    if side_canal:
        rows += [seg((140, 10), (140, 60)), seg((156, 10), (156, 60)),
                 seg((140, -10), (140, -60)), seg((156, -10), (156, -60))]
    else:
        rows += [seg((140, 10), (156, 10)), seg((140, -10), (156, -10))]
    return np.array(rows)


def test_a_side_canal_behind_its_corner_is_a_blind_opening():
    at = blind_opening_ahead(PATH, 100.0, (100.0, 0.0), walls(), 50.0)
    assert at is not None and 140.0 <= at <= 144.0


def test_no_opening_in_a_plain_canal_and_none_out_of_reach():
    assert blind_opening_ahead(PATH, 100.0, (100.0, 0.0), walls(side_canal=False), 50.0) is None
    assert blind_opening_ahead(PATH, 60.0, (60.0, 0.0), walls(), 50.0) is None  # 80 m on


def test_the_opening_is_not_blind_once_the_boat_sees_into_it():
    assert blind_opening_ahead(PATH, 139.5, (139.5, 0.0), walls(), 50.0) is None


def test_a_wall_missing_from_the_scan_never_makes_an_opening_blind():
    # the port quay unseen: that side looks open but nothing hides it; the starboard side
    # canal is still behind its corner
    at = blind_opening_ahead(PATH, 100.0, (100.0, 0.0), walls(port_wall=False), 50.0)
    assert at is not None and at >= 140.0
    only = np.array([seg((0, 10), (300, 10))])  # one wall, nothing across from it
    assert blind_opening_ahead(PATH, 100.0, (100.0, 0.0), only, 50.0) is None


def test_the_speed_cap_brakes_down_to_the_blind_speed():
    assert blind_speed_cap(25.0, 1.0, 0.06) == pytest.approx(2.0)
    assert blind_speed_cap(0.0, 1.0, 0.06) == 1.0
    assert blind_speed_cap(-5.0, 1.0, 0.06) == 1.0


def test_a_boat_over_the_cap_is_asked_for_as_much_less_again():
    """The NMPC follows a slower reference with a lag: a boat 0.3 m/s over the cap is asked
    for 0.3 m/s under it, never less than half the cap; at or under the cap, the cap."""
    assert ask_below_cap(blind_speed_cap(0.0, 1.0, 0.06), 1.3) == pytest.approx(0.7)
    assert ask_below_cap(blind_speed_cap(0.0, 1.0, 0.06), 2.5) == pytest.approx(0.5)
    assert ask_below_cap(blind_speed_cap(25.0, 1.0, 0.06), 1.5) == pytest.approx(2.0)
    assert ask_below_cap(blind_speed_cap(0.0, 1.0, 0.06), 0.8) == 1.0


def test_a_gap_in_the_scanned_quay_is_not_an_opening():
    """A quay the scan missed for 16 m: open beside the route and hidden by the quay before
    it, but no wall runs away from the channel there: no side canal, no slowing."""
    gap = np.array([seg((0, 10), (300, 10)), seg((0, -10), (140, -10)),
                    seg((156, -10), (300, -10))])
    assert blind_opening_ahead(PATH, 100.0, (100.0, 0.0), gap, 50.0) is None
