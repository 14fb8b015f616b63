"""Where the controller's segments come from: known walls, or the simulated LiDAR + detection."""

from __future__ import annotations

import time

import numpy as np

from controller.geometry import clip_segments_to_circle, polyline_legs, simplify_polyline
from scenarios.world.canal import CanalWorld


class KnownWalls:
    """The paper's simulation assumption: the true walls within `range_m` are known exactly.

    The outlines are simplified first (5 cm tolerance), so a straight wall is one segment and
    a bend a chain of chords, as a line detector reports them, not the many short pieces of a
    resampled canal that would crowd the controller's fixed segment slots.
    """

    name = "known-walls"

    def __init__(self, world: CanalWorld, range_m: float = 50.0, air_draft_m: float = np.inf,
                 tolerance_m: float = 0.05):
        self.range_m = range_m
        hit = [o for o in world.obstacles if o.z_bottom_m < air_draft_m]
        lines = [simplify_polyline(p, tolerance_m)
                 for p in world.wall_polylines() + [o.closed for o in hit]]
        self._removed = [None] * len(world.walls) + [o.remove_at_s for o in hit]
        self._lines = lines
        self._legs: dict = {}  # which lines are present -> their legs
        self._vessels = tuple(world.vessels)

    def perceive(self, time_s, true_state, estimated_state):
        """The known walls and, extended to other boats, the true vessels as tracks."""
        from controller.perception.feed import Percept

        return Percept(self.segments(time_s, true_state, estimated_state),
                       self.vessel_tracks(time_s, true_state))

    def vessel_tracks(self, time_s, true_state) -> tuple:
        """The vessels within range, as tracks built from the truth."""
        if not self._vessels:
            return ()
        from controller.perception.tracking import Track

        out = []
        for k, v in enumerate(self._vessels):
            pose = v.pose_at(time_s)
            if np.hypot(*(pose[:2] - np.asarray(true_state)[:2])) <= self.range_m + v.hull.length_m:
                out.append(Track.from_truth(k + 1, pose[:2], v.velocity_at(time_s), pose[2],
                                            v.hull.length_m, v.hull.beam_m))
        return tuple(out)

    def segments(self, time_s, true_state, estimated_state) -> np.ndarray:
        key = tuple(r is None or time_s < r for r in self._removed)
        if key not in self._legs:
            self._legs[key] = polyline_legs([p for p, here in zip(self._lines, key) if here])
        a, b = self._legs[key]
        return clip_segments_to_circle(a, b, np.asarray(true_state)[:2], self.range_m)


class LidarPerception:
    """The simulated three-LiDAR scan at the true pose and time (obstacles removed by then are
    gone), detected into segments placed with the estimated pose (so navigation errors move
    the segments, as on the real boat)."""

    name = "lidar"

    def __init__(self, world: CanalWorld, seed: int = 0, config=None, detection=None):
        from controller.perception.detection import DEFAULT
        from scenarios.sensors.lidar import LidarSimulator

        self.simulator = LidarSimulator(world, config, seed=seed * 7919 + 3)
        self.detection = detection or DEFAULT
        self.points_per_scan: list[int] = []
        self.time_s = {"lidar_scan": 0.0, "detection": 0.0}  # wall time, summed over scans

    def segments(self, time_s, true_state, estimated_state) -> np.ndarray:
        from controller.perception.detection import detect_segments

        true_state = np.asarray(true_state, float)
        t0 = time.perf_counter()
        at = None if time_s is None else float(time_s)
        vessels = self.simulator.world.vessel_obstacles(at) if at is not None else ()
        points = self.simulator.scan(true_state[:3], speed_mps=float(true_state[3]), time_s=at,
                                     extra_obstacles=vessels)
        t1 = time.perf_counter()
        self.points_per_scan.append(len(points))
        if not len(points):
            return None  # an empty scan is a failed one (a working LiDAR sees its own hull)
        found = detect_segments(points, np.asarray(estimated_state, float)[:3], self.detection)
        self.time_s["lidar_scan"] += t1 - t0
        self.time_s["detection"] += time.perf_counter() - t1
        return found
