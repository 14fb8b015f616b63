"""Perception on the boat, one scan at a time: a body-frame cloud (or none) in, the
controller's view out (cleaned static walls, vessel tracks, how old, blind or not).

It chains `detection`, `tracking` and `feed` for a caller that gets raw clouds, as the
bridge does from a live or recorded LiDAR. Nothing a scan holds ends a run: a missing or
empty cloud is a missing scan, one the detector cannot use (odd shape, no finite point, a
pose that is not a number) is counted as failed and treated as missing, and the feed says
when the boat has been blind too long.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import CanalnavError
from .detection import DEFAULT, DetectionConfig, detect_segments, for_surge
from .feed import FeedConfig, Percept, PerceptionView, SegmentFeed
from .tracking import TrackerConfig, VesselTracker


@dataclass(frozen=True)
class PipelineConfig:
    """Detection, tracking (None: no tracking, every segment is a wall) and the feed."""

    detection: DetectionConfig = DEFAULT
    tracking: TrackerConfig | None = field(default_factory=TrackerConfig)
    feed: FeedConfig = FeedConfig()


class ScanPipeline:
    """detect -> track -> clean and bridge gaps, for one boat; `update` once a control period
    with the newest scan (or None when none came)."""

    def __init__(self, config: PipelineConfig | None = None):
        self.config = config or PipelineConfig()
        tracking = self.config.tracking
        if tracking is not None and tracking.detection != self.config.detection:
            from dataclasses import replace

            tracking = replace(tracking, detection=self.config.detection)
        self.tracker = None if tracking is None else VesselTracker(tracking)
        self.feed = SegmentFeed(self.config.feed)
        self.counts = {"scans": 0, "missing": 0, "failed": 0}
        self.last_failure = ""  # why the last failed scan could not be used
        self._last_points = None

    def update(self, time_s: float, points, pose) -> PerceptionView:
        """The view for this period from `points` ((N, 3) body frame, x fwd, y stbd, z down,
        or None) taken at the boat's `pose` (x, y, psi[, ...]) in the world frame."""
        pose = np.asarray(pose, float).reshape(-1)
        detection = self.config.detection
        if len(pose) >= 4 and math.isfinite(pose[3]):  # the state: astern, no wake crop
            detection = for_surge(detection, float(pose[3]))
        pose = pose[:3]
        found = None
        fresh = points is not None and points is not self._last_points
        self._last_points = points
        if not fresh or not len(points):
            self.counts["missing"] += 1
            points = None
        else:
            try:
                points = _usable_cloud(points)
                found = detect_segments(points, pose, detection)
            except (CanalnavError, ValueError, TypeError, IndexError) as exc:
                self.counts["failed"] += 1
                self.last_failure = str(exc)
                points = None
            else:
                self.counts["scans"] += 1
        if self.tracker is None:
            return self.feed.update(time_s, found, pose[:2])
        out = self.tracker.update(time_s, points, pose, found)
        percept = None if found is None else Percept(out.static_segments, out.tracks)
        return self.feed.update(time_s, percept, pose[:2])


def _usable_cloud(points) -> np.ndarray:
    """The finite rows of an (N, 3+) numeric cloud as (M, 3) floats; ValueError if none."""
    arr = np.asarray(points)
    if arr.dtype.kind not in "fiu" or arr.ndim != 2 or arr.shape[1] < 3:
        raise ValueError(f"scan: expected a numeric (N, 3+) cloud, got {arr.dtype} {arr.shape}")
    xyz = arr[:, :3].astype(float, copy=False)
    finite = np.isfinite(xyz).all(axis=1)
    if not finite.any():
        raise ValueError(f"scan: none of its {len(xyz)} points is finite")
    return xyz if finite.all() else xyz[finite]
