"""Round trips through the real decoder libraries: simulated canal sweeps written as Velodyne
packets in a pcap (read back by velodyne-decoder) and as ROS 2 / ROS 1 bags (rosbags); the
points within the format's resolution, the detected walls within 0.1 m of the original's."""

from __future__ import annotations

import numpy as np
import pytest

from bridge.lidar import velodyne_packets as vp
from bridge.lidar.merge import MergedLidar
from bridge.lidar.mount import to_body
from bridge.lidar.rosbag import RosbagSensor
from bridge.lidar.rosbag_write import write_bag
from bridge.lidar.velodyne import VelodynePcapSensor
from controller.errors import InputError
from controller.perception.detection import DEFAULT, detect_segments

from .lidar_rig import BOW_MOUNT, segment_gap_m, simulator, sweep_ros

POSE = (20.0, 0.5, 0.1)


@pytest.fixture(scope="module")
def original():
    return sweep_ros(simulator(), POSE)


def nearest(a, b):  # noqa: D103
    """For each point of b, the distance to the nearest point of a."""
    from scipy.spatial import cKDTree

    return cKDTree(a).query(b)[0]


def test_velodyne_pcap_round_trip(original, tmp_path):
    grid = vp.sweep_grid(original)
    packets = []
    for k in range(3):
        packets += vp.sweep_packets(grid, 5e6 + k * vp.SWEEP_S * 1e6)
    path = tmp_path / "drive.pcap"
    vp.write_pcap(path, packets)
    sensor = VelodynePcapSensor("front", path, "VLP-16")
    sweeps = list(sensor.sweeps())
    assert len(sweeps) >= 2 and sensor.malformed == 0
    stamp, points, times = sweeps[1]  # a whole sweep (the first starts mid-capture)
    assert stamp == pytest.approx(5.0 + 2 * vp.SWEEP_S, abs=2e-3)
    assert times.min() >= stamp - vp.SWEEP_S - 2e-3 and times.max() <= stamp + 2e-3
    # cell by cell (laser, firing): the range to the format's 2 mm; the direction moves to
    # the firing's (the simulator casts on its own column grid, up to 0.1 deg from it)
    back = vp.sweep_grid(points)
    both = (grid > 0) & (back > 0)
    assert both.sum() >= 0.99 * (grid > 0).sum()
    # half the 2 mm unit, and up to 3 mm more: velodyne-decoder puts the lasers up to
    # 0.05 deg off the manual's elevations (e.g. 14.96 for 15 deg), the higher the more
    assert np.abs(back[both] - grid[both]).max() <= 0.001 + 0.003
    gap = nearest(original, points)
    reach = np.linalg.norm(points, axis=1)
    assert np.all(gap <= 0.002 + reach * np.radians(0.1 + 0.011)), gap.max()
    seg_orig = detect_segments(to_body(original, BOW_MOUNT), POSE, DEFAULT)
    seg_back = detect_segments(to_body(points, BOW_MOUNT), POSE, DEFAULT)
    assert len(seg_orig) >= 2
    assert segment_gap_m(seg_orig, seg_back) < 0.1 and segment_gap_m(seg_back, seg_orig) < 0.1


def test_garbage_in_a_pcap_is_counted_and_skipped(original, tmp_path):
    rng = np.random.default_rng(7)
    packets = vp.sweep_packets(vp.sweep_grid(original), 0.0) * 3
    packets = [(i * 1.3e-3, p) for i, (_, p) in enumerate(packets)]
    bad = [(t + 1e-4, rng.integers(0, 256, n, dtype=np.uint8).tobytes())
           for t, n in ((0.01, 1206), (0.02, 100), (0.05, 1206), (0.2, 1500))]
    path = tmp_path / "noisy.pcap"
    vp.write_pcap(path, sorted(packets + bad))
    sensor = VelodynePcapSensor("front", path, "VLP-16")
    assert len(list(sensor.sweeps())) >= 2 and sensor.malformed == 4


@pytest.mark.parametrize("ros", [2, 1])
def test_rosbag_round_trip(original, tmp_path, ros):
    times = np.linspace(0.0, 0.1, len(original))
    sweeps = [(100.0 + 0.1 * k, original, 100.0 + 0.1 * k + times) for k in range(3)]  # Ouster: stamp = start
    path = write_bag(tmp_path / ("bag2" if ros == 2 else "drive.bag"), sweeps, "/os/points", ros)
    sensor = RosbagSensor("front", path)
    got = list(sensor.sweeps())
    assert len(got) == 3 and sensor.malformed == 0
    stamp, points, t = got[1]
    assert stamp == pytest.approx(100.1, abs=1e-9)
    assert np.abs(points - original).max() < 1e-5  # float32 fields
    assert np.abs(t - sweeps[1][2]).max() < 1e-8  # uint32 ns after the stamp
    merged = MergedLidar([RosbagSensor("front", path)], [BOW_MOUNT])
    cloud = merged.scan(0.1, (*POSE, 0.0, 0.0, 0.0))  # the second sweep plays at 0.1 s
    seg_orig = detect_segments(to_body(original, BOW_MOUNT), POSE, DEFAULT)
    seg_back = detect_segments(cloud, POSE, DEFAULT)
    assert segment_gap_m(seg_orig, seg_back) < 0.1 and segment_gap_m(seg_back, seg_orig) < 0.1


def test_a_bag_without_pointclouds_or_with_several_names_the_topics(original, tmp_path):
    a = write_bag(tmp_path / "two", [(1.0, original, None)], "/front/points", 2)
    with pytest.raises(InputError, match=r"no PointCloud2 topic '/side' \(it has /front/points\)"):
        RosbagSensor("x", a, topic="/side")
    with pytest.raises(InputError, match="no such bag"):
        RosbagSensor("x", tmp_path / "none.bag")
