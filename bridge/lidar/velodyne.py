"""Velodyne sensors through `velodyne-decoder`: a recorded `.pcap`, or live UDP packets.

Packets are checked before decoding (1206 bytes, every block's flag 0xFFEE .. 0xFFBB, as
in Velodyne's manuals); a packet that fails, or that the decoder refuses, is counted in
`malformed` and skipped. The decoder cuts sweeps at its cut angle and gives each point its
time relative to the sweep's stamp (the packets' "microseconds past the hour", unwrapped
across hours here). Points come in the decoder's frame (x forward, y left, z up: mount
roll 180 deg for a unit standing upright).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from controller.errors import InputError

from .recorded import RecordedSensor
from .scan import SensorScan, finite_rows, require, udp_listener

PACKET_BYTES = 1206
POSITION_BYTES = 512
BLOCK_FLAGS = (0xEEFF, 0xDDFF, 0xCCFF, 0xBBFF)  # little-endian uint16 of FF EE, FF DD, ...
HOUR_S = 3600.0


def model_names(vd) -> dict[str, object]:
    """Normalised model name -> velodyne_decoder.Model ("VLP-16", "vlp16", "HDL-32E", ...)."""
    return {_norm(k): v for k, v in vd.Model.__members__.items()}


def _norm(text: str) -> str:
    return "".join(c for c in str(text).upper() if c.isalnum())


def decoder_config(model: str | None, what: str):
    vd = require("velodyne_decoder", what)
    if model is None:
        return vd, vd.Config()
    models = model_names(vd)
    if _norm(model) not in models:
        raise InputError(f"{what}: model {model!r} is not one velodyne-decoder knows (one of "
                         f"{', '.join(vd.Model.__members__)})")
    return vd, vd.Config(model=models[_norm(model)])


def packet_ok(data: bytes) -> bool:
    """A data packet's shape: 1206 bytes, 12 blocks of 100 each starting with a block flag."""
    if len(data) != PACKET_BYTES:
        return False
    flags = np.frombuffer(data, "<u2", count=600)[0:600:50]
    return bool(np.isin(flags, BLOCK_FLAGS).all())


class HourUnwrap:
    """Velodyne stamps count microseconds past the hour: make them run on across hours."""

    def __init__(self):
        self.hours = 0
        self.last: float | None = None

    def __call__(self, t: float) -> float:
        if self.last is not None and t < self.last - HOUR_S / 2:
            self.hours += 1
        self.last = t
        return t + self.hours * HOUR_S


class PacketDecoder:
    """Packets in, complete sweeps out: (device stamp s, points (N, 3), point times s)."""

    def __init__(self, model: str | None, what: str):
        vd, config = decoder_config(model, what)
        self.decoder = vd.StreamDecoder(config)
        self.unwrap = HourUnwrap()
        self.malformed = 0
        self.last_device_s: float | None = None

    def feed(self, host_s: float, data: bytes):
        """Decode one packet; the sweep it completes, if it completes one, else None."""
        if not packet_ok(data):
            self.malformed += 1
            return None
        self.last_device_s = self.unwrap(
            int.from_bytes(data[1200:1204], "little") * 1e-6)
        try:
            out = self.decoder.decode(float(host_s), data)
        except (RuntimeError, ValueError):  # e.g. a packet from another model
            self.malformed += 1
            return None
        if out is None:
            return None
        stamp, cloud = out
        # the decoder puts the packets' time past the hour into the hour nearest the host
        # time it was given; on the bridge's clock that is no hour at all: keep our own count
        t = float(stamp.device) % HOUR_S + self.unwrap.hours * HOUR_S
        if self.unwrap.last is not None and t > self.last_device_s + HOUR_S / 2:
            t -= HOUR_S  # the sweep began before the hour turned
        cloud = np.asarray(cloud)
        return t, float(stamp.host), cloud[:, :3].astype(float), t + cloud[:, 4].astype(float)


class VelodynePcapSensor(RecordedSensor):
    """`velodyne-pcap:FILE`: the sweeps of a capture, on the capture's clock (the pcap's
    packet times, shared by every sensor captured on that machine) or the sensor's."""

    def __init__(self, name: str, path, model: str | None = None, clock: str = "host"):
        super().__init__(name, f"velodyne-pcap:{path}")
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"{self.spec}: no such file")
        require("dpkt", self.spec)
        self.model, self.clock = model, clock
        self._decoder = PacketDecoder(model, self.spec)  # checks the model now

    def sweeps(self):
        import dpkt

        decoder = self._decoder
        with open(self.path, "rb") as fh:
            try:
                reader = dpkt.pcap.Reader(fh)
            except (ValueError, dpkt.dpkt.Error) as exc:
                raise InputError(f"{self.spec}: not a pcap file ({exc})") from None
            for host_s, frame in reader:
                data = udp_payload(frame)
                if data is None or len(data) == POSITION_BYTES:
                    continue  # not UDP, or a position (GPS) packet: not ours to count
                out = decoder.feed(host_s, data)
                self.malformed = decoder.malformed
                if out is not None:
                    device_s, host_sweep_s, points, times = out
                    if self.clock == "host":
                        shift = host_sweep_s - device_s
                        yield host_sweep_s, points, times + shift
                    else:
                        yield device_s, points, times


def udp_payload(frame: bytes) -> bytes | None:
    """The UDP payload of an Ethernet frame, or None."""
    import dpkt

    try:
        eth = dpkt.ethernet.Ethernet(frame)
    except (dpkt.dpkt.UnpackError, dpkt.dpkt.NeedData):
        return None
    ip = eth.data
    udp = getattr(ip, "data", None)
    if not isinstance(udp, dpkt.udp.UDP):
        return None
    return bytes(udp.data)


class DeviceClock:
    """Sensor time to bridge time: the smallest (poll time - newest packet's time) over a
    window, as a driver without PTP does (the newest packet of a poll arrived just before
    it; the minimum over many polls is the transport delay)."""

    def __init__(self, window: int = 100):
        self.window = window
        self.candidates: list[float] = []

    def update(self, now_s: float, device_s: float) -> None:
        self.candidates.append(now_s - device_s)
        del self.candidates[:-self.window]

    @property
    def offset_s(self) -> float:
        return min(self.candidates) if self.candidates else math.nan


class VelodyneUdpSensor:
    """`velodyne:PORT`: live packets on a UDP port (the sensor's data port, 2368 by default),
    read without blocking at each control period; sweeps stamped by the sensor's clock
    mapped to the bridge's (DeviceClock)."""

    recorded = False

    def __init__(self, name: str, port: int, model: str | None = None, host: str = "0.0.0.0"):
        self.name, self.spec = name, f"velodyne:{port}"
        self._decoder = PacketDecoder(model, self.spec)
        self.clock = DeviceClock()
        self.sock = udp_listener(self.spec, host, port)
        self.port = self.sock.getsockname()[1]

    @property
    def malformed(self) -> int:
        return self._decoder.malformed

    def poll(self, now_s: float) -> SensorScan | None:
        newest = None
        got = False
        while True:
            try:
                data = self.sock.recv(4096)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break
            got = True
            out = self._decoder.feed(now_s, data)
            if out is not None:
                newest = out
        if got and self._decoder.last_device_s is not None:
            self.clock.update(now_s, self._decoder.last_device_s)
        if newest is None:
            return None
        device_s, _, points, times = newest
        offset = self.clock.offset_s
        pts, times = finite_rows(points, times)
        return SensorScan(pts, times + offset, device_s + offset)

    def close(self) -> None:
        self.sock.close()
