"""Clocks for the MAVLink side: a scaled monotonic clock, and a virtual one for lock-step tests.

Everything in `bridge` reads time through a clock and waits through it, never through
`time` directly. The real clock runs `speedup` times faster than the wall (against a
simulated autopilot); the virtual clock advances only when someone sleeps on it and, on
each tick, runs its registered peers (a simulated autopilot, a relay), so a whole MAVLink
exchange runs deterministically in one thread over real loopback sockets.
"""

from __future__ import annotations

import select
import time
from typing import Callable


class RealClock:
    """Monotonic time in seconds, scaled by `speedup` (1 = real time)."""

    def __init__(self, speedup: float = 1.0):
        if not speedup > 0:
            raise ValueError(f"speedup must be positive, got {speedup}")
        self.speedup = float(speedup)
        self._t0 = time.monotonic()

    def now(self) -> float:
        return (time.monotonic() - self._t0) * self.speedup

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds / self.speedup)

    def wait_readable(self, fd: int, seconds: float) -> None:
        """Sleep up to `seconds`, returning as soon as `fd` has data to read."""
        if seconds <= 0:
            return
        try:
            select.select([fd], [], [], seconds / self.speedup)
        except (OSError, ValueError):  # a closed descriptor: just wait
            time.sleep(seconds / self.speedup)


class VirtualClock:
    """Simulated time that moves in `tick_s` steps when slept on, running peers every tick."""

    def __init__(self, tick_s: float = 0.01):
        self.tick_s = float(tick_s)
        self._ticks = 0
        self._peers: list[Callable[[float], None]] = []

    def add_peer(self, pump: Callable[[float], None]) -> None:
        """Call `pump(now)` on every tick (after time has moved)."""
        self._peers.append(pump)

    def now(self) -> float:
        return self._ticks * self.tick_s

    def wait_readable(self, fd: int, seconds: float) -> None:
        """Data arrives only when the peers run: sleep (whole ticks)."""
        self.sleep(seconds)

    def sleep(self, seconds: float) -> None:
        n = max(1, int(round(seconds / self.tick_s))) if seconds > 0 else 1
        for _ in range(n):
            self._ticks += 1
            now = self.now()
            for pump in self._peers:
                pump(now)
