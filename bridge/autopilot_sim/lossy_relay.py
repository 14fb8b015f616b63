"""A UDP relay with seeded packet loss, latency, outages and injected bytes, for fault tests.

It sits between the bridge (which connects to `relay.port`) and an autopilot listening on
`upstream`, forwarding datagrams both ways on a clock: each datagram is dropped with
probability `loss`, otherwise delivered `latency_s` later; during a cut nothing passes.
With a virtual clock and `pump` as a peer, the same seed drops the same datagrams.
"""

from __future__ import annotations

import heapq
import itertools
import socket

import numpy as np

TO_AUTOPILOT, TO_BRIDGE = "autopilot", "bridge"


class LossyRelay:
    def __init__(self, upstream: tuple[str, int], clock, *, loss: float = 0.0,
                 latency_s: float = 0.0, seed: int = 0, host: str = "127.0.0.1"):
        if not 0.0 <= loss < 1.0:
            raise ValueError(f"loss must lie in [0, 1), got {loss}")
        if latency_s < 0:
            raise ValueError(f"latency must not be negative, got {latency_s}")
        self.upstream = upstream
        self.clock, self.loss, self.latency_s = clock, float(loss), float(latency_s)
        self._rng = np.random.default_rng(seed)
        self._down = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # faces the bridge
        self._down.bind((host, 0))
        self._down.setblocking(False)
        self._up = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # faces the autopilot
        self._up.bind((host, 0))
        self._up.setblocking(False)
        self._bridge_addr = None
        self._queue: list = []  # (due, seq, direction, data)
        self._seq = itertools.count()
        self._cuts: list[tuple[float, float]] = []
        self.counts = {"forwarded": 0, "dropped": 0, "cut": 0, "injected": 0}

    @property
    def port(self) -> int:
        """Where the bridge should connect (udpout:127.0.0.1:PORT)."""
        return self._down.getsockname()[1]

    def cut(self, start_s: float, end_s: float) -> None:
        """Let nothing through, either way, from start_s to end_s on the clock."""
        self._cuts.append((float(start_s), float(end_s)))

    def inject(self, data: bytes, direction: str = TO_AUTOPILOT) -> None:
        """Send raw bytes (garbage, a stranger's message) as if they came over the link."""
        self._send(direction, bytes(data))
        self.counts["injected"] += 1

    def is_cut(self, now: float) -> bool:
        return any(a <= now < b for a, b in self._cuts)

    def pump(self, now: float) -> None:
        """Take in what arrived on both sides, then deliver what is due."""
        for sock, direction in ((self._down, TO_AUTOPILOT), (self._up, TO_BRIDGE)):
            while True:
                try:
                    data, addr = sock.recvfrom(65536)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:  # e.g. ICMP port unreachable from a closed peer
                    continue
                if sock is self._down:
                    self._bridge_addr = addr
                if self.is_cut(now):
                    self.counts["cut"] += 1
                elif self.loss and self._rng.random() < self.loss:
                    self.counts["dropped"] += 1
                else:
                    heapq.heappush(self._queue, (now + self.latency_s, next(self._seq), direction, data))
        while self._queue and self._queue[0][0] <= now + 1e-12:
            _, _, direction, data = heapq.heappop(self._queue)
            if self.is_cut(now):
                self.counts["cut"] += 1
                continue
            self._send(direction, data)
            self.counts["forwarded"] += 1

    def _send(self, direction: str, data: bytes) -> None:
        try:
            if direction == TO_AUTOPILOT:
                self._up.sendto(data, self.upstream)
            elif self._bridge_addr is not None:
                self._down.sendto(data, self._bridge_addr)
        except OSError:
            pass  # a peer that is gone loses the datagram, as on a real link

    def close(self) -> None:
        self._down.close()
        self._up.close()
