"""Recorded scans in a directory, one `.npy`/`.bin` file a scan named by its time in ns."""

from __future__ import annotations

import bisect
import re
from pathlib import Path

import numpy as np

from controller.errors import InputError

from .mount import mount_transform
from .recorded import RecordedSensor

SCAN_SUFFIXES = (".npy", ".bin")


def list_scans(directory) -> list[tuple[int, Path]]:
    """(timestamp ns, path) of each scan file, sorted; InputError names a bad directory."""
    directory = Path(directory)
    if not directory.is_dir():
        raise InputError(f"--lidar replay:{directory}: no such directory")
    files = []
    for path in directory.iterdir():
        if path.suffix.lower() not in SCAN_SUFFIXES or path.name.startswith("."):
            continue
        if not re.fullmatch(r"\d+", path.stem):
            raise InputError(f"{path}: a scan file must be named by its timestamp in "
                             "nanoseconds, e.g. 1596071203150348800.bin")
        files.append((int(path.stem), path))
    if not files:
        raise InputError(f"{directory}: no scans (.npy or .bin files named by their "
                         "timestamp in nanoseconds)")
    files.sort()
    stamps = [ns for ns, _ in files]
    if len(set(stamps)) != len(stamps):
        dup = next(ns for ns, n in zip(stamps, stamps[1:]) if ns == n)
        raise InputError(f"{directory}: two scans with timestamp {dup}")
    return files


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
        files = list_scans(self.directory)
        stamps = [ns for ns, _ in files]
        self.paths = [p for _, p in files]
        self.times_s = [(ns - stamps[0]) * 1e-9 for ns in stamps]
        self.rotation, self.offset = mount_transform(mount)
        self.max_age_s = float(max_age_s)
        self._cached: tuple[int, np.ndarray] | None = None

    def __len__(self) -> int:
        return len(self.paths)

    @property
    def viewpoints(self) -> tuple:
        """The recording sensor's (x_m, y_m, height_m) in the body frame (see `MergedLidar`)."""
        return ((float(self.offset[0]), float(self.offset[1]), -float(self.offset[2])),)

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


class ReplaySensor(RecordedSensor):
    """The same directory as one sensor of a merge (its mount applied by the merge)."""

    def __init__(self, name: str, directory):
        super().__init__(name, f"replay:{directory}")
        self.files = list_scans(directory)

    def sweeps(self):
        for ns, path in self.files:
            try:
                points = read_scan(path)
            except InputError:  # a damaged file mid-drive: counted, skipped
                self.malformed += 1
                continue
            yield ns * 1e-9, points, None


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
