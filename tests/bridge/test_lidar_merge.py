"""The merge of several sensors: de-skew while turning, a sensor unplugged and back, all
silent (perception lost), malformed counts, the configuration file's errors."""

from __future__ import annotations

import numpy as np
import pytest

from bridge.lidar.config import load_lidar_config
from bridge.lidar.deskew import deskew
from bridge.lidar.merge import MergedLidar
from bridge.lidar.scan import SensorScan
from controller.errors import InputError
from controller.perception.detection import DEFAULT, detect_segments

from .lidar_rig import BOW_MOUNT, ROOT, segment_gap_m, simulator, sweep_ros


def test_deskew_while_turning_at_a_tenth_of_a_radian_a_second():
    """A sweep taken over 0.1 s while the boat turns at 0.1 rad/s and goes 2 m/s: each column
    measured from where the boat was then. De-skewed to the sweep's end, its walls are the
    still scan's at that pose; without, they are off by the motion."""
    from bridge.lidar.mount import to_body

    sim = simulator()
    end_pose = np.array([20.0, 0.5, 0.1])
    u, r, sweep = 2.0, 0.1, 0.1
    pieces, times = [], []
    for k in range(10):  # ten slices of the sweep, each from the pose at its time
        dt = -sweep + (k + 0.5) * sweep / 10
        pose = end_pose + np.array([u * dt * np.cos(end_pose[2]), u * dt * np.sin(end_pose[2]),
                                    r * dt])
        pts = to_body(sweep_ros(sim, pose), BOW_MOUNT)
        az = np.arctan2(pts[:, 1] - BOW_MOUNT[1], pts[:, 0] - BOW_MOUNT[0]) % (2 * np.pi)
        part = (az >= 2 * np.pi * k / 10) & (az < 2 * np.pi * (k + 1) / 10)
        pieces.append(pts[part])
        times.append(np.full(part.sum(), dt))
    skewed, t = np.concatenate(pieces), np.concatenate(times)
    still = detect_segments(to_body(sweep_ros(sim, end_pose), BOW_MOUNT), end_pose, DEFAULT)
    raw = detect_segments(skewed, end_pose, DEFAULT)
    fixed = detect_segments(deskew(skewed, t, 0.0, (u, 0.0, r)), end_pose, DEFAULT)
    off_raw, off_fixed = segment_gap_m(raw, still), segment_gap_m(fixed, still)
    print(f"walls from the still scan: {off_raw:.3f} m without de-skew, {off_fixed:.3f} m with")
    assert off_fixed < 0.1 and off_raw > off_fixed


class FakeSensor:
    """Sweeps every 0.1 s except while unplugged; `malformed` set by the test."""

    recorded = False

    def __init__(self, name, y):
        self.name, self.spec = name, f"fake:{name}"
        self.points = np.column_stack([np.linspace(-10, 10, 50), np.full(50, y), np.zeros(50)])
        self.unplugged = []  # (start, end)
        self.malformed = 0

    def poll(self, t):
        if any(a <= t < b for a, b in self.unplugged):
            return None
        return SensorScan(self.points, None, t)

    def close(self):
        pass


def run(merge, until):
    said, lost, sizes = [], None, []
    for k in range(int(round(until / 0.1))):
        t = 0.1 * (k + 1)
        cloud = merge.scan(t, (0, 0, 0, 0, 0, 0))
        sizes.append(0 if cloud is None else len(cloud))
        said += [(round(t, 1), text) for text, _ in merge.pop_notices()]
        lost = lost or merge.lost(t)
    return said, lost, sizes


def test_a_sensor_unplugged_for_3_s_leaves_the_merge_and_comes_back():
    a, b = FakeSensor("port", -5.0), FakeSensor("starboard", 5.0)
    b.unplugged = [(2.0, 5.0)]
    merge = MergedLidar([a, b], [(0,) * 6] * 2)
    said, lost, sizes = run(merge, 7.0)
    assert lost is None
    assert [t for t, _ in said] == [2.3, 5.0]
    assert "'starboard' (fake:starboard) silent for 0.4 s: left out of the merge (1 of 2" in said[0][1]
    assert "back: merged again" in said[1][1]
    assert sizes[10] == 100 and sizes[30] == 50 and sizes[-1] == 100


def test_all_sensors_silent_for_3_s_is_perception_lost():
    a, b = FakeSensor("port", -5.0), FakeSensor("starboard", 5.0)
    a.unplugged = b.unplugged = [(2.0, 5.0)]
    merge = MergedLidar([a, b], [(0,) * 6] * 2, lost_after_s=1.0)
    lost_at = None
    for k in range(60):
        t = 0.1 * (k + 1)
        merge.scan(t, (0,) * 6)
        if merge.lost(t) and lost_at is None:
            lost_at, reason = t, merge.lost(t)
    assert lost_at == pytest.approx(2.9, abs=0.15)
    assert reason.startswith("perception lost: no LiDAR sweep for 1.") and "port, starboard" in reason


def test_malformed_packets_are_counted_and_said_at_most_every_5_s():
    a = FakeSensor("front", 5.0)
    merge = MergedLidar([a], [(0,) * 6])
    merge.scan(0.1, (0,) * 6)
    a.malformed = 3
    merge.scan(0.2, (0,) * 6)
    a.malformed = 9
    merge.scan(0.3, (0,) * 6)
    texts = [t for t, _ in merge.pop_notices()]
    assert texts == ["lidar 'front' (fake:front): 3 malformed packets or messages skipped (3 so far)"]
    assert merge.malformed == {"front": 9}


def test_the_paper_layout_file_and_config_errors(tmp_path):
    cfg = load_lidar_config(ROOT / "bridge" / "lidar" / "lidar_paper_layout.toml")
    assert [s.name for s in cfg.sensors] == ["front", "port", "starboard"]
    assert cfg.sensors[0].kind == "ouster" and cfg.sensors[1].model == "HDL-32E"
    assert cfg.sensors[1].mount[2] == pytest.approx(-2.4) and cfg.lost_after_s == 1.0
    bad = tmp_path / "bad.toml"
    for text, match in (
            ('[[sensor]]\nname = "a"\nsource = "camera:1"\n', r"bad.toml: field 'sensor\[0\].source'"),
            ('[[sensor]]\nname = "a"\nsource = "velodyne:2368"\nmount = { x = 1 }\n',
             r"field 'sensor\[0\].mount.x': unknown field"),
            ('lost_after_s = -1\n[[sensor]]\nname = "a"\nsource = "sim"\n', r"field 'lost_after_s'"),
            ('[[sensor]]\nname = "a"\nsource = "velodyne:2368"\nrole = "up"\n', r"'sensor\[0\].role'")):
        bad.write_text(text)
        with pytest.raises(InputError, match=match):
            load_lidar_config(bad)


def test_a_scenario_lidar_table_is_checked_when_the_bridge_loads_it(tmp_path):
    """The scenario loader keeps [lidar] as it is (scenarios cannot import the bridge); the
    bridge checks it on start: a bad field is an error naming the file and the field."""
    from bridge.lidar.sources import build_lidar
    from scenarios.scenario_file import load_scenario

    base = (ROOT / "scenarios" / "straight.toml").read_text()
    for table, match in (
            ('[[lidar.sensor]]\nname = "f"\nsource = "velodyne:2368"\nmount = { x = 1 }\n',
             r"canal.toml: field 'lidar.sensor\[0\].mount.x': unknown field"),
            ('[lidar]\nlost_after = 2\n[[lidar.sensor]]\nname = "f"\nsource = "sim"\n',
             r"canal.toml: field 'lidar.lost_after': unknown field"),
            ('[[lidar.sensor]]\nname = "f"\nsource = "ouster-pcap:x.pcap"\nmeta = 3\n',
             r"canal.toml: field 'lidar.sensor\[0\].meta': expected a string")):
        path = tmp_path / "canal.toml"
        path.write_text(base + "\n" + table)
        scenario = load_scenario(path)  # loads: the table is the bridge's to check
        with pytest.raises(InputError, match=match):
            build_lidar(["sim"], None, scenario)


def test_the_bridge_judges_free_space_from_where_its_sensors_sit():
    """The merge tells where its sensors are (x, y and height, from the mounts' z down), the
    simulated suite its units, and the bridge's tracker takes them as viewpoints."""
    from bridge.lidar.sim import SimLidarSource
    from bridge.onboard.loop import _perception_for
    from scenarios.scenario_file import load_scenario

    merge = MergedLidar([FakeSensor("bow", 5.0), FakeSensor("stern", -5.0)],
                        [BOW_MOUNT, (-3.0, 0.5, -2.0, 0.0, 0.0, 0.0)])
    assert merge.viewpoints == ((3.5, 0.0, 1.3), (-3.0, 0.5, 2.0))
    assert _perception_for(merge).tracker.config.viewpoints == merge.viewpoints
    sim = SimLidarSource(load_scenario(ROOT / "scenarios" / "straight.toml"))
    assert sim.viewpoints == ((3.5, 0.0, 1.3), (0.0, -1.35, 2.4), (0.0, 1.35, 2.4))
    assert _perception_for(object()).tracker.config.viewpoints == ()  # none known: the origin
