"""Shared for the LiDAR tests: simulated canal sweeps of a level VLP-16 at the bow, and how
close two sets of detected segments are."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bridge.lidar import velodyne_packets as vp
from scenarios.scenario_file import load_scenario
from scenarios.sensors.lidar import LidarConfig, LidarNoise, LidarSimulator

ROOT = Path(__file__).resolve().parents[2]
BOW = (3.5, 0.0, 1.3)  # x, y (m, body) and height above the water of the unit
# the unit upright at the bow: sensor frame x forward, y left, z up
BOW_MOUNT = (3.5, 0.0, -1.3, np.pi, 0.0, 0.0)
QUIET = LidarNoise(range_sigma_m=0.0, dropout=0.0, water_speckle=0.0, spray_points=0)


def simulator(scenario=None, seed=1, noise=QUIET):
    scenario = scenario or load_scenario(ROOT / "scenarios" / "sbend.toml")
    mounts = vp.simulator_mounts("front", *BOW)
    return LidarSimulator(scenario.world, LidarConfig(mounts=mounts, noise=noise), seed=seed)


def sweep_ros(sim, pose) -> np.ndarray:
    """One sweep in the unit's own frame (x forward, y left, z up), own hull left out."""
    scan = sim.scan_labelled(pose)
    keep = scan.labels != 5  # HULL
    return vp.body_to_sensor_ros(np.asarray(scan.points, float)[keep], *BOW)


def segment_gap_m(a, b, step_m: float = 0.5) -> float:
    """How far the walls of `a` lie from those of `b`: each segment of `a` sampled every
    `step_m`, the mean distance of its samples to the nearest segment of `b`; the largest
    over the segments of `a` (a wall cut into other pieces, or a shorter one, still matches)."""
    from controller.geometry import point_segment_distance, segments_to_endpoints

    pa, qa = segments_to_endpoints(np.asarray(a, float).reshape(-1, 4))
    pb, qb = segments_to_endpoints(np.asarray(b, float).reshape(-1, 4))
    worst = 0.0
    for p, q in zip(pa, qa):
        n = max(2, int(np.linalg.norm(q - p) / step_m) + 1)
        samples = p + np.linspace(0, 1, n)[:, None] * (q - p)
        gaps = [float(point_segment_distance(x, pb, qb).min()) for x in samples]
        worst = max(worst, float(np.mean(gaps)))
    return worst


class VelodyneSender:
    """A VLP-16 on loopback as a VirtualClock peer: each sweep's 75 packets go out at their
    own times (sensor rate: a sweep every 99.5 ms), stamped on the sensor's clock, which
    runs `device_offset_s` ahead of the run's. `render(t)` gives the (1800, 16) range grid of
    the sweep that starts at clock time t (the whole sweep seen from the pose then); while
    `unplugged(t)` is true nothing is sent; `garbage(t)` says how many random datagrams to
    add to the sweep starting at t."""

    def __init__(self, clock, port, render, device_offset_s=1234.5, unplugged=None,
                 garbage=None, seed=0):
        import socket
        from collections import deque

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.port, self.render, self.offset = port, render, device_offset_s
        self.unplugged = unplugged or (lambda t: False)
        self.garbage = garbage or (lambda t: 0)
        self.rng = np.random.default_rng(seed)
        self.queue = deque()
        self.next_sweep = None
        self.sent = self.garbage_sent = self.sweeps = 0
        clock.add_peer(self)

    def __call__(self, now):
        if self.next_sweep is None:
            self.next_sweep = now
        while now + 1e-9 >= self.next_sweep:
            start, self.next_sweep = self.next_sweep, self.next_sweep + vp.SWEEP_S
            if self.unplugged(start):
                continue
            self.sweeps += 1
            for t, payload in vp.sweep_packets(self.render(start), (start + self.offset) * 1e6):
                self.queue.append((t - self.offset, payload))
            for _ in range(int(self.garbage(start))):
                n = int(self.rng.choice([1206, 300]))
                self.queue.append((start + 0.05, self.rng.integers(0, 256, n, np.uint8).tobytes()))
            self.queue = type(self.queue)(sorted(self.queue, key=lambda q: q[0]))
        while self.queue and self.queue[0][0] <= now + 1e-9:
            _, payload = self.queue.popleft()
            self.sock.sendto(payload, ("127.0.0.1", self.port))
            self.sent += 1

    def close(self):
        self.sock.close()


class PcapSender:
    """A `.pcap`'s UDP payloads sent on loopback at their capture times (a clock peer, the
    capture's first packet at the peer's first call)."""

    def __init__(self, clock, path, port):
        import socket

        import dpkt

        from bridge.lidar.velodyne import udp_payload

        with open(path, "rb") as fh:
            self.items = [(t, udp_payload(f)) for t, f in dpkt.pcap.Reader(fh)]
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.port, self.start, self.k = port, None, 0
        clock.add_peer(self)

    def __call__(self, now):
        if self.start is None:
            self.start = now - self.items[0][0]
        while self.k < len(self.items) and self.items[self.k][0] + self.start <= now + 1e-9:
            self.sock.sendto(self.items[self.k][1], ("127.0.0.1", self.port))
            self.k += 1

    def close(self):
        self.sock.close()


def moving_sweep_grid(sim, state) -> np.ndarray:
    """The (1800, 16) grid of a sweep that starts at the boat's state (x, y, psi, u, v, r):
    the canal rendered at the start pose, each point then moved into the body frame of the
    moment its laser fires (the sweep's own motion, the constant twist the bridge's
    de-skew undoes), so a moving boat's sweep is skewed as a real one is. The unit's returns
    off the own cabin stay in the sweep, as a real unit's do (they move with the boat)."""
    from bridge.lidar.deskew import deskew

    state = np.asarray(state, float)
    scan = sim.scan_labelled(state[:3])
    points = np.asarray(scan.points, float)
    hull = scan.labels == 5
    body = points[~hull]
    az = np.degrees(np.arctan2(body[:, 1] - BOW[1], body[:, 0] - BOW[0])) % 360.0
    fired = np.round(az / (vp.BLOCK_STEP_DEG / 2)) * vp.SEQUENCE_US * 1e-6  # s after the start
    # from the start's body frame to the one at each firing: the inverse of de-skewing a
    # point measured then back to the start
    moved = deskew(body, -fired, 0.0, state[3:6])
    return vp.sweep_grid(vp.body_to_sensor_ros(np.vstack([moved, points[hull]]), *BOW))
