"""The bridge's LiDAR: sources (simulated, recorded scans, Velodyne, Ouster, ROS bags), the
configuration naming them, de-skewing and the merge into one body-frame cloud a period.

A source's `scan(t, pose)` returns one (N, 3) cloud in the body frame (x forward, y starboard,
z down, origin on the waterline) for the run time t and the boat's pose (x, y, psi, u, v, r),
or None; the bridge hands it to `controller.perception.pipeline`.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from .mount import mount_transform
from .replay import SCAN_SUFFIXES, ReplayLidarSource, read_scan
from .sim import SimLidarSource
from .sources import build_lidar


class LidarSource(Protocol):
    def scan(self, time_s: float, pose) -> np.ndarray | None:
        """(N, 3) body-frame points at `time_s` (seconds from the run's start) for the boat at
        `pose` (x, y, psi[, u, v, r]), or None when there is no scan."""


def parse_lidar_option(text: str):
    """`sim` -> ("sim", None); `replay:DIR` -> ("replay", DIR); other kinds -> (kind, target)."""
    from pathlib import Path

    from .config import parse_source

    kind, target = parse_source(text)
    if kind == "sim":
        return "sim", None
    return kind, Path(target) if kind == "replay" else target


def make_lidar_source(text: str, scenario, seed: int | None = None) -> LidarSource:
    """The source one `--lidar` option names, set up for the scenario (replay: its mount)."""
    kind, target = parse_lidar_option(text)
    if kind == "sim":
        return SimLidarSource(scenario, seed)
    if kind == "replay":
        return ReplayLidarSource(target, scenario.replay_mount)
    return build_lidar([text], None, scenario, seed)


def segments(points, pose, config=None) -> np.ndarray:
    """Wall segments (M, 4) in the inertial frame from a body-frame cloud and the pose
    (controller.perception); no cloud -> no segments."""
    from controller.perception.detection import DEFAULT, detect_segments

    if points is None:
        return np.zeros((0, 4))
    return detect_segments(points, np.asarray(pose, float).reshape(-1)[:3], config or DEFAULT)


__all__ = ["LidarSource", "SimLidarSource", "ReplayLidarSource", "SCAN_SUFFIXES", "build_lidar",
           "make_lidar_source", "mount_transform", "parse_lidar_option", "read_scan", "segments"]
