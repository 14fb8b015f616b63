"""`canalnav detect --lidar SOURCE --at T`: detection on a recorded drive, as a figure."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("velodyne_decoder")

from bridge.lidar import velodyne_packets as vp  # noqa: E402
from bridge.lidar.mount import to_body  # noqa: E402
from bridge.main import main  # noqa: E402
from controller.perception.detection import DEFAULT, detect_segments  # noqa: E402

from .lidar_rig import BOW_MOUNT, segment_gap_m, simulator, sweep_ros  # noqa: E402

POSE = (20.0, 0.5, 0.1)


def test_detect_on_a_velodyne_pcap_at_a_time(tmp_path, capsys):
    sim = simulator()
    poses = [(POSE[0] + 0.2 * k, POSE[1], POSE[2]) for k in range(4)]
    packets = []
    for k, pose in enumerate(poses):
        packets += vp.sweep_packets(vp.sweep_grid(sweep_ros(sim, pose)), 1e6 + k * vp.SWEEP_S * 1e6)
    pcap = tmp_path / "drive.pcap"
    vp.write_pcap(pcap, packets)
    layout = tmp_path / "bow.toml"
    layout.write_text('[[sensor]]\nname = "front"\nsource = "velodyne-pcap:drive.pcap"\n'
                      'model = "VLP-16"\nmount = { x_m = 3.5, z_m = -1.3, roll_deg = 180 }\n')
    out = tmp_path / "d.png"
    # the first whole sweep is the second of the capture (its end plays one sweep after the first)
    csv = tmp_path / "segments.csv"
    assert main(["detect", "--lidar-config", str(layout), "--at", "0.15", "-o", str(out),
                 "--csv", str(csv)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = capsys.readouterr().out
    assert "points at 0.15 s" in text and "0 malformed" in text
    n = int(text.split(" segments")[0].rsplit(" ", 1)[1])
    got = np.loadtxt(csv, delimiter=",", skiprows=1).reshape(-1, 4)
    assert len(got) == n >= 2
    # the walls of one of the simulated sweeps, in the boat's frame, within 0.1 m: the sweep
    # that plays at 0.15 s (its end within 0.15 s of the first sweep's end)
    gaps = []
    for pose in poses:
        truth = detect_segments(to_body(sweep_ros(sim, pose), BOW_MOUNT), (0.0, 0.0, 0.0), DEFAULT)
        gaps.append(max(segment_gap_m(got, truth), segment_gap_m(truth, got)))
    assert min(gaps) < 0.1, gaps
    # a setting changes the detection; bad settings and live sources are one clear line
    assert main(["detect", "--lidar-config", str(layout), "--at", "0.15", "-o", str(out),
                 "--detect-set", "max_height_m=0.2"]) == 0
    fewer = int(capsys.readouterr().out.split(" segments")[0].rsplit(" ", 1)[1])
    assert fewer < n
    for argv, words in ((["--detect-set", "hough=3"], "expected NAME=VALUE"),
                        (["--detect-set", "hough_votes=x"], "hough_votes takes a number"),
                        (["--lidar", "velodyne:2368"], "only recordings"),
                        (["--at", "-1"], "seconds from the first sweep")):
        base = ["detect", "--lidar-config", str(layout), "--at", "0.15", "-o", str(out)]
        if argv[0] == "--lidar":
            base = ["detect", "--at", "0.15", "-o", str(out)]
        if argv[0] == "--at":
            base = ["detect", "--lidar-config", str(layout), "-o", str(out)]
        assert main(base + argv) == 2
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err
    # the same drive on a wrong mount (30 m below the water): every point is cropped away,
    # and the command says so and what to check (issue 35)
    wrong = tmp_path / "wrong.toml"
    wrong.write_text(layout.read_text().replace("z_m = -1.3", "z_m = 30.0"))
    assert main(["detect", "--lidar-config", str(wrong), "--at", "0.15", "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "the crop kept none of the" in err and "roll_deg = 180" in err


def test_detect_without_lidar_is_still_the_simulated_scan(tmp_path, capsys):
    out = tmp_path / "sim.png"
    assert main(["detect", "--at", "95", "-o", str(out)]) == 0
    assert "covered" in capsys.readouterr().out


def test_a_ros_bag_alone_sits_on_ros_convention_by_default(tmp_path, capsys):
    """Issue 35: a ROS 2 bag of PointCloud2 in ROS's convention (x forward, y left, z up) read
    by `detect --lidar rosbag:BAG` on the default mount gave 0 points after the crop and 0
    segments: a source of known convention alone now sits on it (roll 180 deg) unless the
    scenario gives a [sensors.replay_mount]."""
    from types import SimpleNamespace

    from bridge.lidar.rosbag_write import write_bag

    sim = simulator()
    sweeps = [(1.0 + 0.1 * k, sweep_ros(sim, (POSE[0] + 0.2 * k, POSE[1], POSE[2])), None)
              for k in range(3)]
    bag = write_bag(tmp_path / "bag", sweeps, "/points", 2)
    out, csv = tmp_path / "d.png", tmp_path / "d.csv"
    assert main(["detect", "--lidar", f"rosbag:{bag}", "--at", "0.1", "-o", str(out),
                 "--csv", str(csv)]) == 0
    captured = capsys.readouterr()
    assert "the crop kept none" not in captured.err
    kept = int(captured.out.split(" after the crop")[0].rsplit(" ", 1)[1])
    got = np.loadtxt(csv, delimiter=",", skiprows=1).reshape(-1, 4)
    assert kept > 1000 and len(got) >= 2, captured.out
    # the two quays, heading 0.1 rad to starboard of the canal: in the boat's frame they run
    # 0.1 rad to port (read without the roll, y left for starboard, they ran to starboard)
    quays = got[np.argsort(-got[:, 3])[:2]]
    assert np.allclose(quays[:, 2], -POSE[2], atol=0.02), got
    # the scenario's own mount wins; recorded scans keep it, zeros and all
    from bridge.lidar.sources import DRIVER_MOUNT, default_mount

    bow = SimpleNamespace(replay_mount=BOW_MOUNT)
    none = SimpleNamespace(replay_mount=(0.0,) * 6)
    assert default_mount("rosbag", bow) == tuple(BOW_MOUNT)
    assert default_mount("velodyne", none) == DRIVER_MOUNT
    assert default_mount("replay", none) == (0.0,) * 6
