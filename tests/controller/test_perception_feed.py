"""Perception's own output check and the feed that bridges missing scans: what a sensor
delivers is cleaned and counted, never raised."""

import math

import numpy as np
import pytest

from controller.errors import InputError
from controller.perception import (CleaningConfig, FeedConfig, SegmentFeed, clean_segments,
                                   detect_segments)
from controller.perception import detection

WALL = [50.0, 8.0, 0.0, 40.0]


def test_plausible_segments_pass_unchanged_and_in_order():
    segs = np.array([WALL, [50.0, -8.0, 0.0, 40.0], [80.0, 0.0, 1.5, 6.0]])
    out = clean_segments(segs, position=(40.0, 0.0))
    np.testing.assert_array_equal(out.segments, segs)
    assert out.dropped_total == 0


@pytest.mark.parametrize("row, reason", [
    ([1.0, 2.0, 0.0, 0.0], "degenerate"),
    ([1.0, 2.0, 0.0, 0.01], "degenerate"),
    ([1.0, 2.0, 0.0, -3.0], "degenerate"),
    ([np.nan, 2.0, 0.0, 5.0], "non_finite"),
    ([1.0, 2.0, np.inf, 5.0], "non_finite"),
    ([1.0, 2.0, 0.0, 1e6], "too_long"),
    ([900.0, 2.0, 0.0, 5.0], "out_of_range"),
])
def test_each_kind_of_bad_row_is_dropped_and_counted(row, reason):
    out = clean_segments(np.array([WALL, row]), position=(40.0, 0.0))
    np.testing.assert_array_equal(out.segments, [WALL])
    assert out.dropped[reason] == 1 and out.dropped_total == 1


def test_duplicates_keep_the_first_also_with_the_direction_turned_half_a_turn():
    twin = [WALL[0] + 1e-4, WALL[1], WALL[2] + math.pi, WALL[3]]
    out = clean_segments(np.array([WALL, twin, WALL, [50.0, 8.5, 0.0, 40.0]]))
    np.testing.assert_array_equal(out.segments, [WALL, [50.0, 8.5, 0.0, 40.0]])
    assert out.dropped["duplicate"] == 2


def test_many_duplicates_in_bulk_are_found_too():
    segs = np.tile(WALL, (3000, 1))
    out = clean_segments(segs)
    assert len(out.segments) == 1 and out.dropped["duplicate"] == 2999


@pytest.mark.parametrize("garbage", ["walls", [[1, 2, 3]], np.zeros((2, 5)), [[1, 2], [3]]])
def test_malformed_input_is_no_segments_and_one_count(garbage):
    out = clean_segments(garbage)
    assert out.segments.shape == (0, 4) and out.dropped["malformed"] == 1


def test_a_single_row_and_empty_input():
    assert clean_segments(WALL).segments.shape == (1, 4)
    assert clean_segments([]).segments.shape == (0, 4)
    assert clean_segments(None).dropped["malformed"] == 1


def test_bad_cleaning_config_is_a_clear_error():
    with pytest.raises(InputError, match="min_length_m"):
        CleaningConfig(min_length_m=0)
    with pytest.raises(InputError, match="below max_length_m"):
        CleaningConfig(min_length_m=10, max_length_m=5)
    with pytest.raises(InputError, match="max_age_s"):
        FeedConfig(max_age_s=-1)


def test_the_feed_bridges_a_missing_scan_then_says_blind():
    feed = SegmentFeed(FeedConfig(max_age_s=0.3))
    first = feed.update(0.0, np.array([WALL, [1, 1, 0, 0.0]]))
    assert first.fresh and not first.blind and first.dropped["degenerate"] == 1
    gap = [feed.update(t, None) for t in (0.1, 0.2, 0.3)]
    assert all(not v.fresh and not v.blind for v in gap)
    np.testing.assert_array_equal(gap[-1].segments, [WALL])  # the last good ones stand in
    late = feed.update(0.4, None)
    assert late.blind and late.age_s == pytest.approx(0.4)
    np.testing.assert_array_equal(late.segments, [WALL])  # still the best idea of the walls
    back = feed.update(0.5, np.array([WALL]))
    assert back.fresh and not back.blind
    assert feed.missing_scans == 4 and feed.blind_periods == 1
    assert feed.dropped_total["degenerate"] == 1


def test_a_feed_that_never_had_a_scan_is_blind_and_malformed_input_counts_as_missing():
    feed = SegmentFeed()
    view = feed.update(0.0, "garbage")
    assert view.blind and math.isinf(view.age_s) and view.segments.shape == (0, 4)
    assert feed.dropped_total["malformed"] == 1 and feed.missing_scans == 1


def test_the_detector_never_returns_a_segment_shorter_than_its_minimum(monkeypatch):
    """A corner join that moves both ends of a short chord to one point must not give a
    segment of no length (seen on a canal with a sharp corner between explicit quays)."""
    real = detection._join_corners

    def collapse(a, b, cfg):
        a, b = real(a, b, cfg)
        a, b = a.copy(), b.copy()
        b[0] = a[0]  # one segment collapsed to a point
        return a, b

    monkeypatch.setattr(detection, "_join_corners", collapse)
    xs = np.arange(5.0, 40.0, 0.1)
    cloud = np.column_stack([xs, np.full(len(xs), 6.0), np.full(len(xs), -0.5)])
    cloud = np.vstack([cloud, np.column_stack([np.full(60, 20.0), np.arange(-3.0, 3.0, 0.1),
                                               np.full(60, -0.5)])])
    segs = detect_segments(cloud, (0.0, 0.0, 0.0))
    assert len(segs) >= 1 and segs[:, 3].min() >= detection.DEFAULT.min_length_m
