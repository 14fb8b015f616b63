"""Where the controller's segments come from: known walls, or the simulated LiDAR + detection."""

from __future__ import annotations

import time

import numpy as np

from controller.geometry import (clip_segments_to_circle, polyline_legs, segments_cross,
                                 simplify_polyline)
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
        self._last_seen: dict[int, float] = {}  # vessel index -> when last in sight
        self._under_way: set[int] = set()  # vessel indices that have moved (`Track.vessel`)

    def perceive(self, time_s, true_state, estimated_state):
        """The known walls and, extended to other boats, the true vessels as tracks; a vessel
        at rest is an obstacle like a wall (its hull's sides among the segments), as the
        LiDAR tracker hands it on."""
        from controller.perception.feed import Percept

        segs = self.segments(time_s, true_state, estimated_state)
        tracks = self.vessel_tracks(time_s, true_state)
        still = [k for k, tr in enumerate(tracks) if not tr.moving]
        if still:
            rings = [self._vessels[tracks[k].id - 1].outline_at(time_s) for k in still]
            a, b = polyline_legs([np.vstack([r, r[:1]]) for r in rings])
            segs = np.vstack([segs, clip_segments_to_circle(a, b, np.asarray(true_state)[:2],
                                                            self.range_m)])
        return Percept(segs, tracks)

    def vessel_tracks(self, time_s, true_state) -> tuple:
        """The vessels a LiDAR tracker would hand on, as tracks built from the truth: those
        within range and in sight (a corner or the middle of the hull seen past the walls and
        obstacles: nothing is seen through a building), and for the tracker's coasting time
        (`TrackerConfig.max_coast_s`) after one goes out of sight; each a `vessel` once it
        has moved, seen or not (at rest after that, it is passed as a vessel)."""
        if not self._vessels:
            return ()
        from controller.perception.tracking import Track, TrackerConfig

        eye = np.asarray(true_state, float)[:2]
        out = []
        for k, v in enumerate(self._vessels):
            velocity = v.velocity_at(time_s)
            if np.hypot(*velocity) > TrackerConfig.moving_mps:  # seen or not: the truth
                self._under_way.add(k)
            pose = v.pose_at(time_s)
            if np.hypot(*(pose[:2] - eye)) > self.range_m + v.hull.length_m:
                continue
            if self._in_sight(time_s, eye, np.vstack([v.outline_at(time_s), pose[:2]])):
                self._last_seen[k] = time_s
            elif time_s - self._last_seen.get(k, -np.inf) > TrackerConfig.max_coast_s:
                continue
            out.append(Track.from_truth(k + 1, pose[:2], velocity, pose[2], v.hull.length_m,
                                        v.hull.beam_m, under_way=k in self._under_way))
        return tuple(out)

    def _in_sight(self, time_s, eye, points) -> bool:
        """Whether any of `points` is seen from `eye` along a line that crosses none of the
        walls and obstacles present at `time_s` (those a beam at the LiDAR's height meets)."""
        a, b = self._present_legs(time_s)
        lines = np.broadcast_to(eye, points.shape)
        return bool((~segments_cross(lines, points, a, b).any(axis=1)).any())

    def segments(self, time_s, true_state, estimated_state) -> np.ndarray:
        a, b = self._present_legs(time_s)
        return clip_segments_to_circle(a, b, np.asarray(true_state)[:2], self.range_m)

    def _present_legs(self, time_s) -> tuple[np.ndarray, np.ndarray]:
        """The legs (a, b) of the walls and obstacles present at `time_s` (cached)."""
        key = tuple(r is None or time_s < r for r in self._removed)
        if key not in self._legs:
            self._legs[key] = polyline_legs([p for p, here in zip(self._lines, key) if here])
        return self._legs[key]


def tracker_config(lidar_config=None, detection=None):
    """The tracker's settings for the simulated suite: free space judged from where its units
    sit (`TrackerConfig.viewpoints`), with the detection settings given."""
    from controller.perception.detection import DEFAULT
    from controller.perception.tracking import TrackerConfig
    from scenarios.sensors.lidar import LidarConfig

    mounts = (lidar_config or LidarConfig()).mounts
    return TrackerConfig(detection=detection or DEFAULT,
                         viewpoints=tuple((m.x_m, m.y_m, m.height_m) for m in mounts))


class LidarPerception:
    """The simulated three-LiDAR scan at the true pose and time (obstacles removed by then are
    gone, vessels where they are), detected into segments placed with the estimated pose (so
    navigation errors move the segments, as on the real boat); `perceive` also tracks the other
    vessels in the same cloud (`controller.perception.tracking`) and hands the controller the
    walls without the moving hulls, and the tracks. `tracking=False` turns tracking off.
    `cloud_points` > 0 keeps every scan's cloud, decimated to at most that many points, as
    `last_cloud` = (scan time, (N, 3) float32 body frame) for a viewer (None: not kept)."""

    name = "lidar"

    def __init__(self, world: CanalWorld, seed: int = 0, config=None, detection=None,
                 tracking=None, track_here: bool = True, cloud_points: int = 0):
        from controller.perception import opencv

        opencv.cv2()  # (detection's; imported here, when a worker starts)

        from controller.perception.detection import DEFAULT
        from scenarios.sensors.lidar import LidarSimulator

        self.simulator = LidarSimulator(world, config, seed=seed * 7919 + 3)
        self.detection = detection or DEFAULT
        self.tracker = None
        self.tracking = None  # the tracker's config (None: no tracking)
        if tracking is not False:
            self.tracking = tracking or tracker_config(config, self.detection)
            if track_here:  # (else `track` runs in another process: `TrackingHalf`)
                self.tracker = TrackingHalf(self.tracking)
        self.points_per_scan: list[int] = []
        # summed wall time, and this thread's CPU time (the `_cpu` ones) of each part
        self.time_s = {"lidar_scan": 0.0, "detection": 0.0, "tracking": 0.0,
                       "lidar_scan_cpu": 0.0, "detection_cpu": 0.0, "tracking_cpu": 0.0}
        self.cloud_points = int(cloud_points)
        self.last_cloud = None

    def segments(self, time_s, true_state, estimated_state) -> np.ndarray:
        """The detected segments of one scan (None: an empty scan); no tracking."""
        return self._scan_detect(time_s, true_state, estimated_state)[1]

    def perceive(self, time_s, true_state, estimated_state):
        """One scan's static walls and vessel tracks (a `Percept`), or None for an empty scan
        (the tracks are then predicted inside the tracker, and carried by the feed)."""
        cropped, found = self.scan_for_tracking(time_s, true_state, estimated_state)
        if self.tracker is None:
            from controller.perception.feed import Percept

            return None if found is None else Percept(found)
        out = self.tracker.track(time_s, estimated_state, cropped, found)
        self.time_s["tracking"] = self.tracker.time_s
        self.time_s["tracking_cpu"] = self.tracker.cpu_s
        return out

    def scan_for_tracking(self, time_s, true_state, estimated_state):
        """`perceive`'s first half, where the cloud is: the returns the tracker reads
        (`controller.perception.tracking.crop_for_tracker`; None: an empty scan or no
        tracking) and the scan's segments. A worker process sends these, a fraction of the
        cloud, to the process that runs `TrackingHalf.track`: the same tracks."""
        if self.tracking is None:
            return None, self._scan_detect(time_s, true_state, estimated_state)[1]
        cropped, found = self._scan_detect(time_s, true_state, estimated_state, crop=True)
        return (None if found is None else cropped), found

    def _scan_detect(self, time_s, true_state, estimated_state, crop: bool = False):
        """The scan (or with `crop`, the returns the tracker reads) and its segments (None:
        an empty scan)."""
        from controller.perception.detection import detect_segments
        from controller.perception.tracking import crop_for_tracker

        true_state = np.asarray(true_state, float)
        t0, c0 = time.perf_counter(), time.thread_time()
        at = None if time_s is None else float(time_s)
        vessels = self.simulator.world.vessel_obstacles(at) if at is not None else ()
        points = self.simulator.scan(true_state[:3], speed_mps=float(true_state[3]), time_s=at,
                                     extra_obstacles=vessels)
        t1, c1 = time.perf_counter(), time.thread_time()
        self.points_per_scan.append(len(points))
        if self.cloud_points > 0:
            from scenarios.results.foxglove_messages import decimate

            self.last_cloud = (at, decimate(points, self.cloud_points))
        if not len(points):
            return points, None  # an empty scan is a failed one (a LiDAR sees its own hull)
        full = points
        if crop:
            points = crop_for_tracker(points, self.tracking)
            # Detection's crop lies inside the tracker's when they share the detection
            # config: detecting in the tracker's returns gives the same segments, with
            # one pass over the whole cloud instead of two.
        from controller.perception.detection import for_surge

        est = np.asarray(estimated_state, float).reshape(-1)
        detection = for_surge(self.detection, float(est[3])) if len(est) > 3 else self.detection
        found = detect_segments(points if crop and self.tracking.detection == detection
                                else full, np.asarray(estimated_state, float)[:3], detection)
        self.time_s["lidar_scan"] += t1 - t0
        self.time_s["detection"] += time.perf_counter() - t1
        self.time_s["lidar_scan_cpu"] += c1 - c0
        self.time_s["detection_cpu"] += time.thread_time() - c1
        return points, found


class TrackingHalf:
    """`LidarPerception.perceive`'s second half: the vessel tracker on what
    `scan_for_tracking` gave, into the `Percept` the controller takes; `time_s` its summed
    wall time. In the process of the loop when the scans come from a worker process."""

    def __init__(self, config):
        from controller.perception.tracking import VesselTracker

        self.tracker = VesselTracker(config)
        self.time_s = 0.0
        self.cpu_s = 0.0

    def track(self, time_s, estimated_state, cropped, found):
        from controller.perception.feed import Percept

        t0, c0 = time.perf_counter(), time.thread_time()
        out = self.tracker.update(time_s, cropped if found is not None else None,
                                  np.asarray(estimated_state, float)[:3], found, cropped=True)
        self.time_s += time.perf_counter() - t0
        self.cpu_s += time.thread_time() - c0
        if found is None:
            return None
        return Percept(out.static_segments, out.tracks)
