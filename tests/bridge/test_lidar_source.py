"""LiDAR sources: replayed scans (.npy, .bin), their timing and mounting, bad input; the sim."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bridge.lidar import (ReplayLidarSource, SimLidarSource, make_lidar_source,
                                 mount_transform, parse_lidar_option, segments)
from controller.errors import InputError
from scenarios.scenario_file import load_scenario

ROOT = Path(__file__).resolve().parents[2]
T0 = 1596071203150348800  # ns


def wall_cloud(y=5.0, n=400, z=-0.5, seed=0) -> np.ndarray:
    """Points of a wall along x at lateral offset y (body frame, z down), some noise."""
    rng = np.random.default_rng(seed)
    x = np.linspace(-20, 20, n)
    return np.column_stack([x, np.full(n, y) + rng.normal(0, 0.01, n), np.full(n, z)])


def test_parse_lidar_option():
    assert parse_lidar_option("sim") == ("sim", None)
    assert parse_lidar_option("replay:/data/scans") == ("replay", Path("/data/scans"))
    for bad in ("replay:", "live", "Sim"):
        with pytest.raises(InputError, match="expected 'sim', 'replay:DIR', 'velodyne:PORT'"):
            parse_lidar_option(bad)


def test_replay_npy_and_bin_in_timestamp_order(tmp_path):
    a = wall_cloud(5.0)
    b = wall_cloud(-6.0)
    np.save(tmp_path / f"{T0 + 100_000_000}.npy", np.column_stack([b, np.ones(len(b))]))  # (N, 4)
    np.column_stack([a, np.zeros(len(a))]).astype("<f4").tofile(tmp_path / f"{T0}.bin")
    (tmp_path / "timestamps.txt").write_text("not a scan\n")  # other files are ignored
    src = ReplayLidarSource(tmp_path)
    assert len(src) == 2 and src.times_s == pytest.approx([0.0, 0.1])
    first = src.scan(0.05)
    assert first == pytest.approx(a.astype("<f4").astype(float))
    assert src.scan(0.1) == pytest.approx(b)
    assert src.scan(0.5) is src.scan(0.55)  # the newest, cached
    assert src.scan(-0.1) is None
    assert src.scan(0.7) is None  # more than max_age_s after the last scan


def test_replay_mount_moves_points_into_the_body_frame(tmp_path):
    # a sensor 2 m forward, 1.5 m above the waterline (z = -1.5, z down), reporting ROS-style
    # x forward, y left, z up (roll 180 deg) and turned 90 deg to starboard
    pts = np.array([[10.0, 0.0, 0.0], [0.0, 3.0, 1.0]])
    np.save(tmp_path / f"{T0}.npy", pts)
    mount = (2.0, 0.0, -1.5, math.pi, 0.0, math.pi / 2)
    body = ReplayLidarSource(tmp_path, mount).scan(0.0)
    # sensor x (its forward) points to starboard: 10 m ahead of it is 10 m to starboard
    assert body[0] == pytest.approx([2.0, 10.0, -1.5], abs=1e-9)
    # 3 m to the sensor's left (it faces starboard) is 3 m ahead; 1 m up is z 1 m more negative
    assert body[1] == pytest.approx([2.0 + 3.0, 0.0, -2.5], abs=1e-9)
    r, t = mount_transform((0, 0, 0, 0, 0, 0))
    assert r == pytest.approx(np.eye(3)) and t == pytest.approx(np.zeros(3))


def test_replayed_wall_becomes_a_segment_at_the_pose(tmp_path):
    np.save(tmp_path / f"{T0}.npy", wall_cloud(5.0))
    src = ReplayLidarSource(tmp_path)
    pose = (100.0, 50.0, math.pi / 2)  # heading east: starboard is south
    segs = segments(src.scan(0.0, pose), pose)
    assert len(segs) >= 1
    x_c, y_c, theta, length = segs[0]
    assert x_c == pytest.approx(95.0, abs=0.2) and y_c == pytest.approx(50.0, abs=1.0)
    assert abs(math.cos(theta)) < 0.05 and length > 30
    assert segments(None, pose).shape == (0, 4)


def test_nan_rows_dropped_nan_only_scan_refused(tmp_path):
    pts = wall_cloud(5.0, n=10)
    pts[3] = np.nan
    np.save(tmp_path / f"{T0}.npy", pts)
    np.save(tmp_path / f"{T0 + 10**8}.npy", np.full((5, 3), np.nan))
    src = ReplayLidarSource(tmp_path)
    assert len(src.scan(0.0)) == 9
    with pytest.raises(InputError, match=rf"{T0 + 10**8}.npy: every one of its 5 points has a NaN"):
        src.scan(0.1)


def test_empty_scan_is_no_points(tmp_path):
    np.save(tmp_path / f"{T0}.npy", np.zeros((0, 3)))
    assert ReplayLidarSource(tmp_path).scan(0.0).shape == (0, 3)


@pytest.mark.parametrize("name,content,message", [
    ("scan_001.npy", np.zeros((3, 3)), "must be named by its timestamp in nanoseconds"),
    (f"{T0}.npy", np.zeros((3, 2)), r"expected a numeric \(N, 3\+\) array"),
    (f"{T0}.npy", np.zeros(12), r"expected a numeric \(N, 3\+\) array"),
    (f"{T0}.npy", np.array([["a", "b", "c"]]), r"expected a numeric \(N, 3\+\) array"),
    (f"{T0}.bin", np.zeros(6, "<f4"), "not a whole number of float32"),
])
def test_bad_files_are_input_errors(tmp_path, name, content, message):
    path = tmp_path / name
    if name.endswith(".npy"):
        np.save(path, content)
    else:
        content.tofile(path)
    with pytest.raises(InputError, match=message):
        ReplayLidarSource(tmp_path).scan(0.0)


def test_empty_or_missing_directory(tmp_path):
    with pytest.raises(InputError, match="no scans"):
        ReplayLidarSource(tmp_path)
    with pytest.raises(InputError, match="no such directory"):
        ReplayLidarSource(tmp_path / "nope")
    (tmp_path / "garbage.npy").write_bytes(b"not numpy")
    (tmp_path / "garbage.npy").rename(tmp_path / f"{T0}.npy")
    with pytest.raises(InputError, match="not a readable .npy array"):
        ReplayLidarSource(tmp_path).scan(0.0)


def test_sim_source_sees_the_scenario_canal_and_is_seeded():
    scenario = load_scenario(ROOT / "scenarios" / "straight.toml")
    pose = np.array([50.0, 0.0, 0.0, 1.5, 0.0, 0.0])
    a = SimLidarSource(scenario, seed=3).scan(0.0, pose)
    b = SimLidarSource(scenario, seed=3).scan(0.0, pose)
    assert a.shape[1] == 3 and len(a) > 1000 and np.array_equal(a, b)
    segs = segments(a, pose)
    # the canal is 20 m wide around y = 0: walls at y = -10 and y = +10
    ys = sorted(round(float(s[1])) for s in segs if s[3] > 10)
    assert -10 in ys and 10 in ys
    assert isinstance(make_lidar_source("sim", scenario), SimLidarSource)


def test_make_replay_source_uses_the_scenario_mount(tmp_path):
    scenario = load_scenario(ROOT / "scenarios" / "straight.toml")
    scenario = replace(scenario, replay_mount=(1.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    np.save(tmp_path / f"{T0}.npy", np.array([[0.0, 0.0, 0.0]]))
    src = make_lidar_source(f"replay:{tmp_path}", scenario)
    assert src.scan(0.0) == pytest.approx(np.array([[1.0, 0.0, 0.0]]))
