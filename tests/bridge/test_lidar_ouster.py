"""Ouster round trips through ouster-sdk: simulated canal sweeps of an OS1-64 at the bow
written as the SDK's lidar packets with metadata (a pcap, and UDP on loopback), read back
by the SDK's reader; ranges to the format's 1 mm, points within the beams' geometry, the
detected walls within 0.1 m of the original cloud's. Bad packets are counted."""

from __future__ import annotations

import math
import socket

import numpy as np
import pytest

pytest.importorskip("ouster.sdk.core")

from bridge.lidar import ouster_packets as op  # noqa: E402
from bridge.lidar.config import parse_lidar_table  # noqa: E402
from bridge.lidar.merge import MergedLidar  # noqa: E402
from bridge.lidar.mount import to_body  # noqa: E402
from bridge.lidar.ouster import OusterPcapSensor, OusterUdpSensor  # noqa: E402
from bridge.lidar.sources import open_sensor  # noqa: E402
from controller.errors import InputError  # noqa: E402
from controller.perception.detection import DEFAULT, detect_segments  # noqa: E402
from scenarios.scenario_file import load_scenario  # noqa: E402
from scenarios.sensors.lidar import LidarConfig, LidarMount, LidarSimulator  # noqa: E402

from .lidar_rig import BOW, BOW_MOUNT, QUIET, ROOT, segment_gap_m  # noqa: E402

POSE = (20.0, 0.5, 0.1)
BEAM_ORIGIN_M = 0.0158  # the OS1's lidar_origin_to_beam_origin_mm: off the spin axis


@pytest.fixture(scope="module")
def info():
    return op.sensor_info()


@pytest.fixture(scope="module")
def original(info):
    """One sweep of the canal in the unit's frame, each beam cast along its pixels' rays
    (one single-channel simulated unit a beam, at the lidar's optical centre)."""
    d, o = op.rays(info)
    lift = float(o[..., 2].mean())  # the optical centre above the sensor's base
    mounts = []
    for i in range(d.shape[0]):
        az = np.arctan2(-d[i, :, 1], d[i, :, 0])  # clockwise from ahead, as the simulator
        el = math.asin(float(d[i, 0, 2]))
        mounts.append(LidarMount(f"os/{i}", BOW[0], BOW[1], BOW[2] + lift, 1,
                                 yaw_rad=float(az[0] % (2 * np.pi / d.shape[1])),
                                 elevation_min_rad=el, elevation_max_rad=el,
                                 columns=d.shape[1], min_range_m=0.5, max_range_m=100.0))
    scenario = load_scenario(ROOT / "scenarios" / "sbend.toml")
    sim = LidarSimulator(scenario.world, LidarConfig(mounts=tuple(mounts), noise=QUIET), seed=1)
    scan = sim.scan_labelled(POSE)
    keep = scan.labels != 5  # own hull
    pts = np.asarray(scan.points, float)[keep]
    d_ = pts - (BOW[0], BOW[1], -BOW[2])
    return np.column_stack([d_[:, 0], -d_[:, 1], -d_[:, 2]])  # x forward, y left, z up


def capture(info, original, tmp_path, sweeps=3):
    img = op.range_image(info, original)
    packets = []
    for k in range(sweeps):
        packets += op.frame_packets(info, img, k, 1000.0 + 0.1 * k, 20.0 + 0.1 * k)
    path = tmp_path / "front.pcap"
    op.write_pcap(path, packets)
    op.write_metadata(tmp_path / "front.json", info)
    return img, packets, path


def test_ouster_pcap_round_trip(info, original, tmp_path):
    from scipy.spatial import cKDTree

    img, _, path = capture(info, original, tmp_path)
    assert (img > 0).sum() >= 0.97 * len(original)  # (nearly) a pixel each
    sensor = OusterPcapSensor("front", path)  # front.json found beside it
    sweeps = list(sensor.sweeps())
    assert len(sweeps) == 3 and sensor.malformed == 0
    stamp, points, times = sweeps[1]
    w = info.format.columns_per_frame
    # host clock: the sweep's last column when its packet was captured (20.2 s, 1 column
    # time after it was measured); each point's time its column's, on that clock
    assert stamp == pytest.approx(20.2, abs=1e-6)
    assert times.min() >= stamp - 0.1 and times.max() <= stamp
    steps = np.diff(np.unique(times)) * 10 * w  # in column times (1/10240 s), to the ns
    assert np.abs(steps - np.round(steps)).max() < 1e-4 and np.round(steps).min() == 1
    assert len(points) == (img > 0).sum()
    # the ranges are the written ones to the format's 1 mm (checked on the frame itself)
    from ouster.sdk import core, pcap

    src = pcap.PcapPacketSource(str(path), sensor_info=[info])
    batcher, frame = core.FrameBatcher(info), core.LidarFrame(info)
    for _, p in src:
        if batcher.batch(p, frame):
            break
    src.close()
    assert np.array_equal(np.asarray(frame.field("RANGE")), img)
    # each point read back lies on its pixel's ray, within 1 mm in range and the beam's
    # origin (16 mm off the axis, which the simulator's rays start from) of the original
    gap, _ = cKDTree(original).query(points)
    assert np.all(gap <= 0.001 + BEAM_ORIGIN_M), gap.max()
    seg_orig = detect_segments(to_body(original, BOW_MOUNT), POSE, DEFAULT)
    seg_back = detect_segments(to_body(points, BOW_MOUNT), POSE, DEFAULT)
    assert len(seg_orig) >= 2
    print(f"ouster pcap: {len(points)} points, largest gap {gap.max() * 1000:.1f} mm, walls "
          f"{segment_gap_m(seg_orig, seg_back):.3f} / {segment_gap_m(seg_back, seg_orig):.3f} m")
    assert segment_gap_m(seg_orig, seg_back) < 0.1 and segment_gap_m(seg_back, seg_orig) < 0.1


def test_ouster_pcap_through_the_config_and_the_merge(info, original, tmp_path):
    _, _, path = capture(info, original, tmp_path)
    moved = tmp_path / "meta" / "os1.json"
    moved.parent.mkdir()
    (tmp_path / "front.json").rename(moved)
    table = {"sensor": [{"name": "front", "source": "ouster-pcap:front.pcap",
                         "meta": "meta/os1.json", "mount": {"x_m": 3.5, "z_m": -1.3,
                                                            "roll_deg": 180}}]}
    cfg = parse_lidar_table(table, "layout.toml", "", tmp_path)
    assert cfg.sensors[0].metadata == str(moved)
    merged = MergedLidar([open_sensor(cfg.sensors[0])], [cfg.sensors[0].mount])
    assert merged.scan(0.05, (*POSE, 0, 0, 0)) is not None  # the first sweep at 0
    cloud = merged.scan(0.1, (*POSE, 0, 0, 0))  # the second
    seg = detect_segments(cloud, POSE, DEFAULT)
    seg_orig = detect_segments(to_body(original, BOW_MOUNT), POSE, DEFAULT)
    assert segment_gap_m(seg_orig, seg) < 0.1
    with pytest.raises(InputError, match=r"no metadata JSON .*front.json does not exist"):
        OusterPcapSensor("front", path)
    bad = tmp_path / "bad.json"
    bad.write_text('{"not": "metadata"}')
    with pytest.raises(InputError, match=r"ouster-pcap:.*metadata .*bad.json: not Ouster"):
        OusterPcapSensor("front", path, bad)


def test_ouster_live_udp_clock_and_garbage(info, original, tmp_path):
    """Packets sent on loopback as a sensor would: sweeps come when complete, stamped on
    the sensor's clock mapped to the bridge's (the packets' own stamps + the smallest
    transport delay seen); garbage and another sensor's packets are counted."""
    op.write_metadata(tmp_path / "os.json", info)
    sensor = OusterUdpSensor("front", "127.0.0.1", tmp_path / "os.json", lidar_port=0,
                             listen="127.0.0.1")
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        img = op.range_image(info, original)
        w = info.format.columns_per_frame
        per = w // info.format.columns_per_packet
        device0, bridge0 = 5000.0, 2.0  # sensor time 5000 s is bridge time 2 s (+ delay)
        got = []
        for k in range(3):
            packets = op.frame_packets(info, img, k, device0 + 0.1 * k)
            for j, p in enumerate(packets):
                out.sendto(p.buf.tobytes(), ("127.0.0.1", sensor.port))
                if j == per // 2 and k == 1:
                    out.sendto(b"\x00" * 100, ("127.0.0.1", sensor.port))  # too short
                    other = bytearray(p.buf.tobytes())
                    other[4:8] = b"\x01\x02\x03\x04"  # another sensor's init id
                    out.sendto(bytes(other), ("127.0.0.1", sensor.port))
                if (j + 1) % 8 == 0:  # polled every 8 packets (12.5 ms of sweep)
                    cols = (j + 1) * info.format.columns_per_packet
                    now = bridge0 + 0.1 * k + cols / (10.0 * w) + 0.002  # 2 ms transport delay
                    scan = sensor.poll(now)
                    if scan is not None:
                        got.append((now, scan))
        assert sensor.malformed == 2
        assert len(got) >= 2  # the frame batcher hands a sweep when its last packet is in
        now, scan = got[1]
        # the sweep's last column: sensor time device0 + 0.1 + 1023/10240 -> bridge time +2 ms
        assert scan.stamp_s == pytest.approx(bridge0 + 0.1 + (w - 1) / (10 * w) + 0.002, abs=2e-3)
        assert scan.stamp_s <= now + 1e-9
        assert scan.times_s.max() <= scan.stamp_s + 1e-9
        assert scan.times_s.min() >= scan.stamp_s - 0.1
        assert len(scan.points) == (img > 0).sum()
    finally:
        out.close()
        sensor.close()


def test_ouster_metadata_fetched_from_the_sensors_http_api(info, tmp_path):
    """Without a saved metadata JSON the sensor's own is fetched over its HTTP API (the
    SDK's client): the beams and the packet format are the sensor's; a host that does not
    answer is a clear error saying how to give the metadata instead."""
    import subprocess
    import sys
    from pathlib import Path

    from bridge.lidar.ouster import fetch_metadata

    op.write_metadata(tmp_path / "os.json", info)
    server = subprocess.Popen([sys.executable, str(Path(__file__).with_name("ouster_http.py")),
                               str(tmp_path / "os.json")], stdout=subprocess.PIPE, text=True)
    try:
        port = int(server.stdout.readline())
        sensor = OusterUdpSensor("front", f"127.0.0.1:{port}", None, lidar_port=0,
                                 listen="127.0.0.1")
        got = sensor.info
        assert got.sn == info.sn and got.prod_line == info.prod_line
        assert got.format.columns_per_frame == info.format.columns_per_frame
        assert got.format.pixels_per_column == info.format.pixels_per_column
        assert np.allclose(got.beam_altitude_angles, info.beam_altitude_angles)
        sensor.close()
    finally:
        server.kill()
        server.wait()
    dead = socket.socket()
    dead.bind(("127.0.0.1", 0))
    closed = dead.getsockname()[1]
    dead.close()  # (nothing listens there now)
    with pytest.raises(InputError, match=r"cannot fetch the sensor's metadata from "
                       rf"127\.0\.0\.1:{closed} .*give a saved metadata JSON"):
        fetch_metadata(f"127.0.0.1:{closed}", f"ouster:127.0.0.1:{closed}")
