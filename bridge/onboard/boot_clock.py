"""The autopilot's clock (time since boot, as its messages carry it) mapped to the bridge's.

ArduPilot answers TIMESYNC with its own time since boot (`AP_HAL::micros64()` in ns, the
clock of `time_boot_ms`), so a round trip sent at `t_s` and answered at `t_r` (bridge clock)
gives the offset as NTP does, `(t_s + t_r) / 2 - tc1`, exact when the two directions take
equally long; the sample with the shortest round trip among the recent ones has the least
queueing in it. The messages check it: none can arrive before it was made, so the smallest
`arrival - time_boot` over the last half minute bounds the offset from above (plus the
fastest one-way trip). When TIMESYNC is not answered, or disagrees with that bound (an
autopilot that answers on another clock), the offset is that bound less the one-way delay.

An autopilot's clock can stall and jump (SITL under load fell 0.6 s behind in one go): the
old samples then describe another clock, and the half minute of arrivals would hold the old
offset that long. So once TIMESYNC and the arrivals have agreed, a TIMESYNC answer whose
offset differs from the one in use by more than `JUMP_S` (and more than its own round trip)
is a step of the autopilot's clock: the mapping is anchored again on that answer alone, the
arrivals' history starts afresh, and the step is counted (`jumps`, `last_jump_s`) for the
log. An autopilot on another clock never agrees, so it never re-anchors.
"""

from __future__ import annotations

import statistics
from collections import deque

LAG_WINDOW_S = 30.0  # how far back the smallest arrival lag is taken
TOLERANCE_S = 0.005  # clock readings, rounding to whole milliseconds
JUMP_S = 0.02  # a TIMESYNC offset this far from the one in use: the autopilot's clock stepped


class BootClock:
    """time_boot (autopilot seconds) -> bridge clock seconds, from TIMESYNC and arrivals."""

    def __init__(self, window: int = 9, lag_window_s: float = LAG_WINDOW_S):
        self._syncs: deque[tuple[float, float]] = deque(maxlen=window)  # (round trip, offset)
        self._lags: deque[tuple[float, float]] = deque()  # (arrival, lag), lags increasing
        self.lag_window_s = float(lag_window_s)
        self.fallback_delay_s = 0.0  # one-way delay when TIMESYNC is not answered (ACK trips)
        self._agreed = False  # TIMESYNC and the arrivals agreed since the last anchoring
        self.jumps = 0  # steps of the autopilot's clock seen (re-anchorings)
        self.last_jump_s = 0.0  # the last one: + the autopilot's clock fell behind

    def reset(self) -> None:
        """The autopilot rebooted: its clock starts again."""
        self._syncs.clear()
        self._lags.clear()
        self._agreed = False

    def timesync(self, sent_s: float, received_s: float, tc1_s: float) -> None:
        """A TIMESYNC round trip: sent and answered on the bridge's clock, `tc1_s` the
        autopilot's time when it answered. One that says the autopilot's clock stepped
        anchors the mapping again (see the module's docstring)."""
        rtt = received_s - sent_s
        if rtt < 0:
            return
        offset = 0.5 * (sent_s + received_s) - tc1_s
        current = self._timesync_offset() if self._agreed else None
        if current is not None and abs(offset - current) > max(JUMP_S, rtt + TOLERANCE_S):
            self.jumps += 1
            self.last_jump_s = offset - current
            self._syncs.clear()
            self._lags.clear()  # stamped on the old clock; the next messages refill them
            self._agreed = False
        self._syncs.append((rtt, offset))

    def message(self, time_boot_s: float, arrival_s: float) -> None:
        """A message stamped `time_boot_s` by the autopilot arrived at `arrival_s`."""
        lag = arrival_s - time_boot_s
        while self._lags and self._lags[-1][1] >= lag:
            self._lags.pop()
        self._lags.append((arrival_s, lag))
        while self._lags[0][0] < arrival_s - self.lag_window_s:
            self._lags.popleft()

    @property
    def round_trip_s(self) -> float | None:
        """Median TIMESYNC round trip (None before one was answered)."""
        return statistics.median(r for r, _ in self._syncs) if self._syncs else None

    @property
    def delay_s(self) -> float:
        """One-way link delay: half the median TIMESYNC round trip, else the fallback."""
        rtt = self.round_trip_s
        return self.fallback_delay_s if rtt is None else 0.5 * rtt

    @property
    def source(self) -> str:
        """How the offset is known: "timesync", "arrivals" or "none"."""
        if self._timesync_offset() is not None:
            return "timesync"
        return "arrivals" if self._lags else "none"

    def _timesync_offset(self) -> float | None:
        if not self._syncs:
            return None
        rtt, offset = min(self._syncs)
        if self._lags:
            fastest = self._lags[0][1] - offset  # the quickest message's one-way trip
            if not -TOLERANCE_S <= fastest <= rtt + TOLERANCE_S:
                return None  # TIMESYNC on another clock than time_boot_ms
            self._agreed = True
        return offset

    @property
    def offset_s(self) -> float | None:
        """bridge time = time_boot + offset (None before anything arrived)."""
        offset = self._timesync_offset()
        if offset is not None:
            return offset
        if self._lags:
            return self._lags[0][1] - self.delay_s
        return None

    def to_bridge(self, time_boot_s: float) -> float | None:
        """When (bridge clock) the autopilot's `time_boot_s` was."""
        offset = self.offset_s
        return None if offset is None else time_boot_s + offset
