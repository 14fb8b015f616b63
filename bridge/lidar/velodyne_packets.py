"""Writing VLP-16 data packets and `.pcap` captures (for tests, demos and tool checks).

The layout is the one in Velodyne's VLP-16 manual: a 1206-byte UDP payload of 12 data
blocks (flag 0xFFEE, azimuth in 0.01 deg, then two firing sequences of 16 lasers, each a
distance in 2 mm units and a reflectivity byte), a 4-byte time stamp in microseconds past
the hour and the factory bytes (0x37 strongest return, 0x22 VLP-16). A firing sequence
lasts 55.296 us and the lasers within it fire 2.304 us apart, so a laser's azimuth is its
block's plus the rotation over its firing offset (the manual's "precision azimuth").

Here the unit turns 0.4 deg a block (about 603 rpm, a 99.5 ms sweep), so every firing
sequence sits on a 0.2 deg grid and a whole sweep is 900 blocks, 75 packets.
"""

from __future__ import annotations

import math
import socket
import struct

import numpy as np

# Laser id -> elevation (deg), from the manual (interleaved: -15, +1, -13, +3, ...).
VLP16_ELEVATIONS_DEG = (-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15)
FIRING_US, SEQUENCE_US = 2.304, 55.296
BLOCK_US = 2 * SEQUENCE_US
BLOCK_STEP_DEG = 0.4
BLOCKS_PER_SWEEP = int(round(360.0 / BLOCK_STEP_DEG))  # 900
SEQUENCES = 2 * BLOCKS_PER_SWEEP  # 1800 firing sequences a sweep, 0.2 deg apart
PACKETS_PER_SWEEP = BLOCKS_PER_SWEEP // 12  # 75
SWEEP_S = BLOCKS_PER_SWEEP * BLOCK_US * 1e-6
DISTANCE_UNIT_M = 0.002
RETURN_STRONGEST, PRODUCT_VLP16 = 0x37, 0x22


def laser_azimuth_offsets_deg() -> np.ndarray:
    """(16,) each laser's azimuth past its sequence's: rotation over its firing time."""
    rate = BLOCK_STEP_DEG / BLOCK_US  # deg per us
    return np.arange(16) * FIRING_US * rate


def sweep_grid(points_ros: np.ndarray, tolerance_deg: float = 0.3) -> np.ndarray:
    """Sensor-frame points (x forward, y left, z up) -> (1800, 16) ranges (0 = no return),
    each point in the cell of the laser and firing sequence nearest its direction (the
    nearer point wins a cell). Points farther than `tolerance_deg` in elevation from every
    laser are left out."""
    p = np.asarray(points_ros, float).reshape(-1, 3)
    r = np.linalg.norm(p, axis=1)
    ok = r > 0
    p, r = p[ok], r[ok]
    el = np.degrees(np.arcsin(np.clip(p[:, 2] / r, -1, 1)))
    az = np.degrees(np.arctan2(-p[:, 1], p[:, 0])) % 360.0
    lasers = np.asarray(VLP16_ELEVATIONS_DEG, float)
    laser = np.abs(el[:, None] - lasers[None, :]).argmin(axis=1)
    near = np.abs(el - lasers[laser]) <= tolerance_deg
    seq = np.round((az - laser_azimuth_offsets_deg()[laser]) / (BLOCK_STEP_DEG / 2)).astype(int)
    seq %= SEQUENCES
    laser, seq, r = laser[near], seq[near], r[near]
    grid = np.full((SEQUENCES, 16), np.inf)
    np.minimum.at(grid, (seq, laser), r)
    grid[~np.isfinite(grid)] = 0.0
    return grid


def sweep_packets(grid: np.ndarray, start_us: float, reflectivity: int = 100) -> list[tuple[float, bytes]]:
    """A (1800, 16) range grid as the 75 packets of one sweep, starting at azimuth 0:
    (time s, payload) with the time stamp of each packet's first firing."""
    units = np.round(np.asarray(grid, float) / DISTANCE_UNIT_M)
    units = np.where((units > 0) & (units < 65536), units, 0).astype("<u2")
    out = []
    for k in range(PACKETS_PER_SWEEP):
        t_us = start_us + k * 12 * BLOCK_US
        body = bytearray()
        for b in range(12 * k, 12 * k + 12):
            body += struct.pack("<HH", 0xEEFF, int(round(b * BLOCK_STEP_DEG * 100)) % 36000)
            cells = np.zeros(32, dtype=[("d", "<u2"), ("r", "u1")])
            cells["d"] = units[2 * b:2 * b + 2].reshape(-1)
            cells["r"] = reflectivity
            body += cells.tobytes()
        stamp = int(round(t_us)) % 3_600_000_000
        body += struct.pack("<IBB", stamp, RETURN_STRONGEST, PRODUCT_VLP16)
        out.append((t_us * 1e-6, bytes(body)))
    return out


def simulator_mounts(name: str, x_m: float, y_m: float, height_m: float, yaw_rad: float = 0.0):
    """The VLP-16's beams for `scenarios.sensors.lidar.LidarSimulator`: one single-channel
    mount a laser at its elevation, 1800 columns a turn (a level unit: spin axis vertical).
    The simulator casts every beam on its column grid, so a laser's firing offset (up to
    0.125 deg) is not rendered: `sweep_grid` puts each point in the firing nearest it."""
    from scenarios.sensors.lidar import LidarMount

    return tuple(
        LidarMount(f"{name}/{i}", x_m, y_m, height_m, 1, yaw_rad=yaw_rad,
                   elevation_min_rad=math.radians(el), elevation_max_rad=math.radians(el),
                   columns=SEQUENCES, min_range_m=0.5, max_range_m=100.0)
        for i, el in enumerate(VLP16_ELEVATIONS_DEG))


def body_to_sensor_ros(points_body: np.ndarray, x_m: float, y_m: float, height_m: float,
                       yaw_rad: float = 0.0) -> np.ndarray:
    """Body-frame points (z down) into a level sensor's own frame (x forward, y left, z up)."""
    d = np.asarray(points_body, float) - (x_m, y_m, -height_m)
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    xs, ys = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]  # sensor frame, y right
    return np.column_stack([xs, -ys, -d[:, 2]])


def write_pcap(path, packets, port: int = 2368, src=("192.168.1.201", 2368),
               dst="255.255.255.255") -> None:
    """Packets [(time s, payload)] as a pcap of Ethernet/IPv4/UDP frames, as a capture on
    the sensor's network would hold them."""
    import dpkt

    with open(path, "wb") as fh:
        writer = dpkt.pcap.Writer(fh)
        for t, payload in packets:
            writer.writepkt(udp_frame(payload, src, dst, port), ts=t)


def udp_frame(payload: bytes, src, dst, port: int) -> bytes:
    import dpkt

    udp = dpkt.udp.UDP(sport=src[1], dport=port, data=payload)
    udp.ulen = len(udp)
    ip = dpkt.ip.IP(src=socket.inet_aton(src[0]), dst=socket.inet_aton(dst), p=dpkt.ip.IP_PROTO_UDP,
                    data=udp, ttl=64)
    ip.len = len(ip)
    eth = dpkt.ethernet.Ethernet(src=b"\x60\x76\x88\x00\x00\x01", dst=b"\xff" * 6,
                                 type=dpkt.ethernet.ETH_TYPE_IP, data=ip)
    return bytes(eth)
