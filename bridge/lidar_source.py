"""Where the bridge's point clouds come from: the simulated LiDAR, or recorded scans.

A `LidarSource` returns one merged cloud in the body frame (x forward, y starboard, z down,
origin on the waterline) for a time and pose, or None when it has nothing; the bridge hands
it to `controller.perception.pipeline` (detection, vessel tracking, cleaning, gaps). A live driver can join
later behind the same `scan` method.
"""

from __future__ import annotations

import bisect
import re
from pathlib import Path
from typing import Protocol

import numpy as np

from controller.errors import InputError
from scenarios.sensors.lidar import sensor_rotation

SCAN_SUFFIXES = (".npy", ".bin")


class LidarSource(Protocol):
    def scan(self, time_s: float, pose) -> np.ndarray | None:
        """(N, 3) body-frame points at `time_s` (seconds from the run's start) for the boat at
        `pose` (x, y, psi[, u, ...]), or None when there is no scan."""


class SimLidarSource:
    """The scenario's canal seen by the simulated LiDAR (scenarios.sensors.lidar) at the given
    pose and time: obstacles removed by then are gone, the scenario's vessels are where they
    are on the run's clock (seconds since the bridge took control).

    On the bridge that pose is the autopilot's EKF estimate (the bridge knows no other), so
    the simulated walls sit where the boat believes it is: navigation errors do not shift the
    detected segments as they would on a real boat. A plant that knows the true pose can wrap
    its own source.
    """

    name = "sim"

    def __init__(self, scenario, seed: int | None = None):
        from scenarios.sensors.lidar import LidarSimulator

        seed = scenario.seed if seed is None else int(seed)
        self.simulator = LidarSimulator(scenario.world, seed=seed * 7919 + 3)

    def scan(self, time_s: float, pose) -> np.ndarray:
        p = np.asarray(pose, float).reshape(-1)
        speed = float(p[3]) if len(p) > 3 else 0.0
        t = float(time_s)
        return self.simulator.scan(p[:3], speed_mps=speed, time_s=t,
                                   extra_obstacles=self.simulator.world.vessel_obstacles(t))


def mount_transform(mount) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) from sensor to body frame for a mount (x, y, z m, roll, pitch, yaw rad):
    p_body = R p_sensor + t, R = Rz(yaw) Ry(pitch) Rx(roll) as `scenarios.sensors.lidar.LidarMount`.
    A sensor that reports x forward, y left, z up (ROS) has roll = 180 deg."""
    x, y, z, roll, pitch, yaw = (float(v) for v in mount)
    return sensor_rotation(roll, pitch, yaw), np.array([x, y, z])


class ReplayLidarSource:
    """Recorded scans, one file per scan named by its timestamp in nanoseconds.

    `.npy`: an (N, 3+) array (x, y, z[, intensity, ...]); `.bin`: float32 x, y, z, intensity
    records (as KITTI-style datasets ship them). Scans play relative to the first one's
    timestamp: `scan(t)` is the newest scan not newer than t, None before the first or more
    than `max_age_s` after the last. Points are moved from the sensor into the body frame with
    the scenario's `replay_mount`; rows with NaN or inf are dropped.
    """

    name = "replay"

    def __init__(self, directory, mount=(0.0,) * 6, max_age_s: float = 0.5):
        self.directory = Path(directory)
        if not self.directory.is_dir():
            raise InputError(f"--lidar replay:{directory}: no such directory")
        files = []
        for path in self.directory.iterdir():
            if path.suffix.lower() not in SCAN_SUFFIXES or path.name.startswith("."):
                continue
            if not re.fullmatch(r"\d+", path.stem):
                raise InputError(f"{path}: a scan file must be named by its timestamp in "
                                 "nanoseconds, e.g. 1596071203150348800.bin")
            files.append((int(path.stem), path))
        if not files:
            raise InputError(f"{self.directory}: no scans (.npy or .bin files named by their "
                             "timestamp in nanoseconds)")
        files.sort()
        stamps = [ns for ns, _ in files]
        if len(set(stamps)) != len(stamps):
            dup = next(ns for ns, n in zip(stamps, stamps[1:]) if ns == n)
            raise InputError(f"{self.directory}: two scans with timestamp {dup}")
        self.paths = [p for _, p in files]
        self.times_s = [(ns - stamps[0]) * 1e-9 for ns in stamps]
        self.rotation, self.offset = mount_transform(mount)
        self.max_age_s = float(max_age_s)
        self._cached: tuple[int, np.ndarray] | None = None

    def __len__(self) -> int:
        return len(self.paths)

    def scan(self, time_s: float, pose=None) -> np.ndarray | None:
        i = bisect.bisect_right(self.times_s, float(time_s) + 1e-9) - 1
        if i < 0 or (i == len(self.paths) - 1 and time_s - self.times_s[i] > self.max_age_s):
            return None
        if self._cached is None or self._cached[0] != i:
            self._cached = (i, self.load(i))
        return self._cached[1]

    def load(self, i: int) -> np.ndarray:
        """Scan `i` in the body frame, (N, 3) float64, finite rows only."""
        raw = read_scan(self.paths[i])
        return raw @ self.rotation.T + self.offset


def read_scan(path: Path) -> np.ndarray:
    """One scan file -> (N, 3) sensor-frame points with finite coordinates."""
    path = Path(path)
    if path.suffix.lower() == ".npy":
        try:
            arr = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputError(f"{path}: not a readable .npy array ({exc})") from None
        if arr.dtype.kind not in "fiu" or arr.ndim != 2 or arr.shape[1] < 3:
            raise InputError(f"{path}: expected a numeric (N, 3+) array of x, y, z[, ...], "
                             f"got {arr.dtype} {arr.shape}")
        xyz = arr[:, :3].astype(float)
    else:
        data = np.fromfile(path, dtype="<f4")
        if data.size % 4:
            raise InputError(f"{path}: {path.stat().st_size} bytes is not a whole number of "
                             "float32 (x, y, z, intensity) records of 16 bytes")
        xyz = data.reshape(-1, 4)[:, :3].astype(float)
    if not len(xyz):
        return np.zeros((0, 3))
    finite = np.isfinite(xyz).all(axis=1)
    if not finite.any():
        raise InputError(f"{path}: every one of its {len(xyz)} points has a NaN or inf coordinate")
    return xyz[finite]


def parse_lidar_option(text: str) -> tuple[str, Path | None]:
    """`sim` -> ("sim", None); `replay:DIR` -> ("replay", DIR)."""
    if text == "sim":
        return "sim", None
    if text.startswith("replay:") and len(text) > len("replay:"):
        return "replay", Path(text[len("replay:"):])
    raise InputError(f"--lidar {text!r}: expected 'sim' or 'replay:DIR'")


def make_lidar_source(text: str, scenario, seed: int | None = None) -> LidarSource:
    """The source an option names, set up for the scenario."""
    kind, directory = parse_lidar_option(text)
    if kind == "sim":
        return SimLidarSource(scenario, seed)
    return ReplayLidarSource(directory, scenario.replay_mount)


def segments(points, pose, config=None) -> np.ndarray:
    """Wall segments (M, 4) in the inertial frame from a body-frame cloud and the pose
    (controller.perception); no cloud -> no segments."""
    from controller.perception.detection import DEFAULT, detect_segments

    if points is None:
        return np.zeros((0, 4))
    return detect_segments(points, np.asarray(pose, float).reshape(-1)[:3], config or DEFAULT)
