"""Writing Ouster lidar packets, metadata and `.pcap` captures (for tests, demos and tool
checks), through ouster-sdk's own writer (`frame_to_packets`, `pcap.record`).

A cloud in the sensor's frame (x forward, y left, z up) becomes a range image: each point
goes to the pixel (beam, column) whose ray points nearest its direction, with the range
along that ray in the format's unit (1 mm); the nearer point wins a pixel. The SDK's own
XYZ table (`XYZLut`: per pixel a direction and an offset, the beam's origin off the axis
as the sensor's intrinsics give it) is the one model of the rays, so what is written is
what the SDK reads back.
"""

from __future__ import annotations

import numpy as np

from .scan import require

LIDAR_PORT, IMU_PORT = 7502, 7503
FIRMWARE = "v3.1.0"  # metadata as a 3.x firmware writes it: the profile below, ports set
PROFILE = "RNG19_RFL8_SIG16_NIR16"  # the default single-return profile since firmware 2.x
SERIAL, INIT_ID = 992210000123, 5431  # made up: a sensor's serial and initialisation id


def sensor_info(mode: str = "1024x10", lidar_port: int = LIDAR_PORT):
    """An OS1-64's metadata (the SDK's default intrinsics for `mode`), as a sensor sends it."""
    core = require("ouster.sdk.core", "ouster packets")
    info = core.SensorInfo.from_default(getattr(core.LidarMode, "_" + mode))
    info.fw_rev = FIRMWARE
    info.sn, info.init_id = SERIAL, INIT_ID  # every packet carries them: checked on reading
    profile = getattr(core.UDPProfileLidar, PROFILE)
    fmt = info.format
    fmt.udp_profile_lidar = profile
    info.format = fmt
    cfg = info.config
    cfg.udp_profile_lidar, cfg.lidar_mode = profile, getattr(core.LidarMode, "_" + mode)
    cfg.udp_port_lidar, cfg.udp_port_imu = int(lidar_port), IMU_PORT
    info.config = cfg
    return info


def rays(info) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) unit directions and (H, W, 3) origins (m) of the pixels, staggered (a
    column is one measurement: all its pixels fire together)."""
    core = require("ouster.sdk.core", "ouster packets")
    lut = core.XYZLut(info, use_extrinsics=False)
    h, w = info.format.pixels_per_column, info.format.columns_per_frame
    d = np.asarray(lut.direction, float).reshape(h, w, 3)
    return d / np.linalg.norm(d, axis=2, keepdims=True), np.asarray(lut.offset, float).reshape(h, w, 3)


def range_image(info, points_ros: np.ndarray, max_angle_deg: float = 0.3) -> np.ndarray:
    """Sensor-frame points -> (H, W) staggered ranges in mm (uint32, 0 = no return). A point
    farther than `max_angle_deg` from every pixel's ray is left out."""
    from scipy.spatial import cKDTree

    d, o = rays(info)
    h, w = d.shape[:2]
    p = np.asarray(points_ros, float).reshape(-1, 3)
    p = p[np.linalg.norm(p, axis=1) > 0.1]
    u = p / np.linalg.norm(p, axis=1, keepdims=True)
    tree = cKDTree(d.reshape(-1, 3))
    _, idx = tree.query(u)
    for _ in range(2):  # again from the beam's own origin (a few mm off the axis)
        q = p - o.reshape(-1, 3)[idx]
        dist, idx = tree.query(q / np.linalg.norm(q, axis=1, keepdims=True))
    near = dist <= np.radians(max_angle_deg)
    idx, p = idx[near], p[near]
    r = np.einsum("ij,ij->i", d.reshape(-1, 3)[idx], p - o.reshape(-1, 3)[idx])
    img = np.full(h * w, np.inf)
    np.minimum.at(img, idx, r)
    img[~np.isfinite(img) | (img <= 0)] = 0.0
    return np.round(img * 1000.0).reshape(h, w).astype(np.uint32)


def frame_packets(info, range_mm: np.ndarray, frame_id: int, start_s: float,
                  host_start_s: float | None = None):
    """One sweep (a staggered (H, W) range image) as the SDK's lidar packets: column j
    measured at `start_s` + j / (W * fps) on the sensor's clock; each packet stamped as
    captured (`host_start_s` + the same, default the sensor's time) for the pcap."""
    core = require("ouster.sdk.core", "ouster packets")
    h, w = range_mm.shape
    frame = core.LidarFrame(info)
    frame.frame_id = int(frame_id) % 65536
    frame.field("RANGE")[:] = range_mm
    frame.field("REFLECTIVITY")[:] = np.where(range_mm > 0, 50, 0)
    frame.measurement_id[:] = np.arange(w)
    column_s = 1.0 / (w * info.format.fps)
    frame.timestamp[:] = np.round((start_s + np.arange(w) * column_s) * 1e9).astype(np.uint64)
    frame.status[:] = 1  # every column valid
    pf = core.PacketFormat.from_info(info)
    packets = core.frame_to_packets(frame, pf, info.init_id, info.sn)
    host0 = start_s if host_start_s is None else host_start_s
    per = pf.columns_per_packet
    for k, packet in enumerate(packets):
        packet.host_timestamp = int(round((host0 + (k + 1) * per * column_s) * 1e9))
    return packets


def write_pcap(path, packets, lidar_port: int = LIDAR_PORT) -> int:
    """The packets as a pcap (Ethernet/IPv4/UDP, as the SDK records a sensor)."""
    pcap = require("ouster.sdk.pcap", "ouster packets")
    return pcap.record(packets, str(path), lidar_port=lidar_port)


def write_metadata(path, info) -> None:
    """The metadata JSON beside a capture (what the sensor's HTTP API gives)."""
    from pathlib import Path

    Path(path).write_text(info.to_json_string())
