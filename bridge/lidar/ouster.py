"""Ouster sensors through ouster-sdk: a recorded `ouster-pcap:FILE.pcap` with its metadata
JSON, or a live `ouster:HOST` (packets on the lidar UDP port, 7502 unless the metadata or
`lidar_port` says otherwise).

The metadata (`metadata` in the sensor's config; for a pcap, else FILE.json beside it; live,
else fetched from the sensor's HTTP API) tells the SDK the packet format and the beams.
The SDK's `FrameBatcher` gathers packets into sweeps and its `XYZLut` turns ranges into
points in the sensor frame (x forward, y left, z up: mount roll 180 deg upright). Each
point's time is its column's time stamp (sensor clock, ns); a sweep is stamped with its
last valid column. A packet of the wrong size or another sensor's (init id, serial) is
counted in `malformed` and skipped.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from controller.errors import InputError

from .recorded import RecordedSensor
from .scan import SensorScan, finite_rows, require, udp_listener
from .velodyne import DeviceClock


def load_metadata(path, what: str):
    """The SensorInfo in a metadata JSON; InputError names the file and what is wrong."""
    core = require("ouster.sdk.core", what)
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise InputError(f"{what}: metadata {p}: cannot read it ({exc.strerror})") from None
    try:
        info, issues = core.parse_and_validate_metadata(text)
    except (RuntimeError, ValueError) as exc:
        raise InputError(f"{what}: metadata {p}: not Ouster sensor metadata ({exc})") from None
    if info is None:
        raise InputError(f"{what}: metadata {p}: not Ouster sensor metadata ({issues})")
    return info


class FrameDecoder:
    """Packets in, sweeps out: (device stamp s, points (N, 3), point times s)."""

    def __init__(self, info):
        core = require("ouster.sdk.core", "ouster")
        self.core, self.info = core, info
        self.format = core.PacketFormat.from_info(info)
        self.batcher = core.FrameBatcher(info)
        self.frame = core.LidarFrame(info)
        self.xyz = core.XYZLut(info, use_extrinsics=False)
        self.malformed = 0
        self.last_device_s: float | None = None  # newest column time of the newest packet

    def packet(self, data: bytes, host_s: float):
        """A LidarPacket from a datagram, or None (counted) if it is not one of ours."""
        if len(data) != self.format.lidar_packet_size:
            self.malformed += 1
            return None
        packet = self.core.LidarPacket(self.format)
        packet.buf[:] = np.frombuffer(data, np.uint8)
        packet.host_timestamp = int(round(host_s * 1e9))
        return packet

    def feed(self, packet):
        """One LidarPacket; the sweep it completes, if it completes one, else None."""
        if packet.validate(self.info, self.format) != self.core.PacketValidationFailure.NONE:
            self.malformed += 1
            return None
        stamps = self.format.packet_header(self.core.ColHeader.TIMESTAMP, packet.buf)
        if len(stamps) and stamps.max() > 0:
            self.last_device_s = float(stamps.max()) * 1e-9
        if not self.batcher.batch(packet, self.frame):
            return None
        return self.sweep(self.frame)

    def sweep(self, frame):
        ranges = np.asarray(frame.field("RANGE"))
        valid_col = (np.asarray(frame.status) & 1).astype(bool)
        keep = (ranges > 0) & valid_col[None, :]
        if not keep.any():
            return None
        points = np.asarray(self.xyz(frame), float)[keep]
        col_s = np.asarray(frame.timestamp, float) * 1e-9
        times = np.broadcast_to(col_s[None, :], ranges.shape)[keep]
        stamp = float(col_s[valid_col].max())
        return stamp, points, times


class OusterPcapSensor(RecordedSensor):
    """`ouster-pcap:FILE`: the sweeps of a capture, on the capture's clock (its packet
    times, shared by every sensor captured on that machine) or the sensor's."""

    def __init__(self, name: str, path, metadata=None, clock: str = "host"):
        super().__init__(name, f"ouster-pcap:{path}")
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"{self.spec}: no such file")
        meta = Path(metadata) if metadata else self.path.with_suffix(".json")
        if not meta.is_file():
            raise InputError(f"{self.spec}: no metadata JSON ({meta} does not exist): give the "
                             "sensor's metadata file as 'metadata' in the LiDAR config")
        self.info = load_metadata(meta, self.spec)
        self.clock = clock

    def sweeps(self):
        pcap = require("ouster.sdk.pcap", self.spec)
        decoder = FrameDecoder(self.info)
        try:
            source = pcap.PcapPacketSource(str(self.path), sensor_info=[self.info])
        except (RuntimeError, ValueError) as exc:
            raise InputError(f"{self.spec}: not a pcap the Ouster SDK can read ({exc})") from None
        try:
            for _, packet in source:
                if not isinstance(packet, decoder.core.LidarPacket):
                    continue  # IMU, zone packets: not ours
                out = decoder.feed(packet)
                self.malformed = decoder.malformed + source.size_error_count + source.id_error_count
                if out is None:
                    continue
                stamp, points, times = out
                if self.clock == "host":
                    shift = packet.host_timestamp * 1e-9 - decoder.last_device_s
                    yield stamp + shift, points, times + shift
                else:
                    yield stamp, points, times
            self.malformed = decoder.malformed + source.size_error_count + source.id_error_count
        finally:
            source.close()


class OusterUdpSensor:
    """`ouster:HOST`: live lidar packets on the UDP port the sensor sends to, read without
    blocking at each control period; sweeps on the sensor's clock mapped to the bridge's
    (DeviceClock, as for Velodyne)."""

    recorded = False

    def __init__(self, name: str, host: str, metadata=None, lidar_port: int | None = None,
                 listen: str = "0.0.0.0"):
        self.name, self.spec = name, f"ouster:{host}"
        if metadata:
            info = load_metadata(metadata, self.spec)
        else:
            info = fetch_metadata(host, self.spec)
        self.info = info  # the sensor's metadata (`SensorInfo`): saved, or fetched from it
        port = lidar_port or info.config.udp_port_lidar or 7502
        self._decoder = FrameDecoder(info)
        self.clock = DeviceClock()
        self.sock = udp_listener(self.spec, listen, port)
        self.port = self.sock.getsockname()[1]

    @property
    def malformed(self) -> int:
        return self._decoder.malformed

    def poll(self, now_s: float) -> SensorScan | None:
        newest, got = None, False
        while True:
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError, OSError):
                break
            got = True
            packet = self._decoder.packet(data, now_s)
            if packet is None:
                continue
            out = self._decoder.feed(packet)
            if out is not None:
                newest = out
        if got and self._decoder.last_device_s is not None:
            self.clock.update(now_s, self._decoder.last_device_s)
        if newest is None:
            return None
        device_s, points, times = newest
        offset = self.clock.offset_s
        pts, times = finite_rows(points, times)
        return SensorScan(pts, times + offset, device_s + offset)

    def close(self) -> None:
        self.sock.close()


def fetch_metadata(host: str, what: str):
    """The sensor's metadata over its HTTP API (the SDK's client)."""
    sensor = require("ouster.sdk.sensor", what)
    core = require("ouster.sdk.core", what)
    try:
        text = sensor.SensorHttp.create(host, 10).metadata(10)
    except Exception as exc:  # noqa: BLE001 - the SDK raises its own types for a dead host
        raise InputError(f"{what}: cannot fetch the sensor's metadata from {host} ({exc}); "
                         "give a saved metadata JSON as 'metadata' in the LiDAR config") from None
    return core.SensorInfo(text)


def open_ouster(cfg):
    """The sensor for an `ouster:` or `ouster-pcap:` source in the configuration."""
    if cfg.kind == "ouster-pcap":
        return OusterPcapSensor(cfg.name, cfg.target, cfg.metadata, cfg.clock)
    return OusterUdpSensor(cfg.name, cfg.target, cfg.metadata, cfg.lidar_port)
