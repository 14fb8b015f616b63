"""Recorded sensors (pcap files, bags, scan directories) played on the bridge's clock.

A recording's sweeps are read lazily, in order; the sensor time `origin_s` plays at run
time 0 (the merge sets it to the earliest first sweep among its recorded sensors, so
sensors recorded together stay together). `poll(t)` returns the newest sweep whose end is
not later than t, once; a sweep that cannot be decoded is counted in `malformed` and skipped.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from .scan import SensorScan, finite_rows

Sweep = tuple  # (stamp_s, points (N, 3) sensor frame, times_s (N,) or None), sensor clock


class RecordedSensor:
    """A recording as a sensor; subclasses give `sweeps()` (sensor-clock seconds)."""

    recorded = True

    def __init__(self, name: str, spec: str):
        self.name, self.spec = name, spec
        self.malformed = 0
        self.origin_s: float | None = None
        self._iter: Iterator[Sweep] | None = None
        self._next: Sweep | None = None
        self._done = False

    def sweeps(self) -> Iterator[Sweep]:  # pragma: no cover - abstract
        raise NotImplementedError

    def _advance(self) -> None:
        if self._iter is None:
            self._iter = iter(self.sweeps())
        self._next = next(self._iter, None)
        self._done = self._next is None

    def first_time_s(self) -> float | None:
        """The sensor time of the first sweep (None for an empty recording)."""
        if self._iter is None:
            self._advance()
        return None if self._next is None else float(self._next[0])

    def poll(self, now_s: float) -> SensorScan | None:
        if self._iter is None:
            self._advance()
        if self.origin_s is None:
            self.origin_s = self.first_time_s() or 0.0
        newest = None
        while self._next is not None and self._next[0] - self.origin_s <= now_s + 1e-9:
            newest = self._next
            self._advance()
        if newest is None:
            return None
        stamp, points, times = newest
        pts, times = finite_rows(points, times)
        shift = -self.origin_s
        return SensorScan(pts, None if times is None else times + shift, float(stamp) + shift)

    def close(self) -> None:
        close = getattr(self._iter, "close", None)
        if close is not None:
            close()
