"""The onboard perception chain (detect -> track -> feed) on hand-made clouds: walls become
segments, a moving hull becomes a track and leaves the walls, and nothing a scan holds
raises: missing, repeated, malformed and empty clouds are counted and bridged."""

from __future__ import annotations

import numpy as np
import pytest

from controller.perception.feed import FeedConfig
from controller.perception.pipeline import PipelineConfig, ScanPipeline


def wall_points(y, x0=-40.0, x1=50.0, step=0.1, z=-0.5):
    x = np.arange(x0, x1, step)
    return np.column_stack([x, np.full(len(x), y), np.full(len(x), z)])


def hull_points(cx, cy, length=8.0, beam=2.5, step=0.1, z=-0.6):
    """The outline of a box hull, all round (body frame of a boat at the origin)."""
    xs = np.arange(cx - length / 2, cx + length / 2, step)
    ys = np.arange(cy - beam / 2, cy + beam / 2, step)
    ring = np.vstack([np.column_stack([xs, np.full(len(xs), cy - beam / 2)]),
                      np.column_stack([xs, np.full(len(xs), cy + beam / 2)]),
                      np.column_stack([np.full(len(ys), cx - length / 2), ys]),
                      np.column_stack([np.full(len(ys), cx + length / 2), ys])])
    return np.column_stack([ring, np.full(len(ring), z)])


CANAL = np.vstack([wall_points(-8.0), wall_points(8.0)])
POSE = (0.0, 0.0, 0.0)


def test_walls_become_fresh_segments():
    view = ScanPipeline().update(0.0, CANAL, POSE)
    assert view.fresh and not view.blind and len(view.segments) >= 2
    assert set(np.round(np.abs(view.segments[:, 1]))) == {8.0}


def test_a_vessel_coming_the_other_way_is_tracked_and_not_a_wall():
    p = ScanPipeline()
    view = None
    for k in range(15):
        t = 0.1 * k
        view = p.update(t, np.vstack([CANAL, hull_points(30.0 - 2.0 * t, 3.0)]), POSE)
    assert len(view.tracks) == 1
    tr = view.tracks[0]
    assert tr.moving and tr.velocity[0] == pytest.approx(-2.0, abs=0.3)
    # what is left for the NMPC are the walls
    assert np.all(np.abs(np.abs(view.segments[:, 1]) - 8.0) < 0.3)


def test_without_tracking_every_segment_is_a_wall():
    p = ScanPipeline(PipelineConfig(tracking=None))
    view = None
    for k in range(15):
        t = 0.1 * k
        view = p.update(t, np.vstack([CANAL, hull_points(30.0 - 2.0 * t, 3.0)]), POSE)
    assert view.tracks == () and np.any(np.abs(np.abs(view.segments[:, 1]) - 8.0) > 1.0)


def test_missing_and_repeated_scans_are_bridged_then_blind():
    p = ScanPipeline(PipelineConfig(feed=FeedConfig(max_age_s=0.25)))
    first = p.update(0.0, CANAL, POSE)
    again = p.update(0.1, None, POSE)
    assert not again.fresh and not again.blind
    np.testing.assert_array_equal(again.segments, first.segments)
    same = CANAL.copy()
    p.update(0.2, same, POSE)
    repeated = p.update(0.3, same, POSE)  # the same cloud again: no new scan
    assert not repeated.fresh and not repeated.blind
    later = [p.update(0.4 + 0.1 * k, None, POSE) for k in range(3)]
    assert later[-1].blind and p.counts["missing"] == 5 and p.counts["scans"] == 2


@pytest.mark.parametrize("cloud", [np.zeros((10, 2)), np.full((20, 3), np.nan),
                                   np.array([["a", "b", "c"]]), np.zeros((0, 3))])
def test_a_cloud_the_detector_cannot_use_never_raises(cloud):
    p = ScanPipeline()
    good = p.update(0.0, CANAL, POSE)
    view = p.update(0.1, cloud, POSE)
    assert not view.fresh and len(view.segments) == len(good.segments)
    assert p.counts["failed"] + p.counts["missing"] == 1
