"""Message streams of the simulated autopilot: default rates, SET_MESSAGE_INTERVAL, due times.

Intervals are in seconds of the autopilot's boot clock; None is off. A stream keeps its
average rate (the next send is one interval after the previous due time) but never sends a
burst to catch up after a gap. A reboot forgets requested rates, as ArduPilot does.
"""

from __future__ import annotations

# Message ids (common.xml) of the streams the simulator can send.
HEARTBEAT = 0
SYS_STATUS = 1
ATTITUDE = 30
LOCAL_POSITION_NED = 32
GLOBAL_POSITION_INT = 33
GPS_GLOBAL_ORIGIN = 49
SERVO_OUTPUT_RAW = 36
RC_CHANNELS = 65
EKF_STATUS_REPORT = 193

# Default interval (s) of each stream; None: off until asked for.
DEFAULT_INTERVALS: dict[int, float | None] = {
    HEARTBEAT: 1.0,
    SYS_STATUS: 1.0,
    EKF_STATUS_REPORT: 1.0,
    ATTITUDE: 0.25,
    LOCAL_POSITION_NED: 0.25,
    GLOBAL_POSITION_INT: 0.25,
    RC_CHANNELS: None,
    SERVO_OUTPUT_RAW: None,
    GPS_GLOBAL_ORIGIN: None,  # on request (and once when the EKF sets its origin)
}

# MAV_DATA_STREAM groups of the legacy REQUEST_DATA_STREAM, as ArduPilot fills them.
DATA_STREAM_GROUPS: dict[int, tuple[int, ...]] = {
    2: (SYS_STATUS,),  # EXTENDED_STATUS
    3: (RC_CHANNELS, SERVO_OUTPUT_RAW),  # RC_CHANNELS
    6: (GLOBAL_POSITION_INT, LOCAL_POSITION_NED),  # POSITION
    10: (ATTITUDE,),  # EXTRA1
    12: (EKF_STATUS_REPORT,),  # EXTRA3
}


class Streams:
    """Interval and next due time of each stream."""

    def __init__(self):
        self.intervals: dict[int, float | None] = {}
        self._due: dict[int, float] = {}
        self.reset(0.0)

    def reset(self, now_s: float) -> None:
        """Back to the default rates, every stream due now."""
        self.intervals = dict(DEFAULT_INTERVALS)
        self._due = {mid: now_s for mid in self.intervals}

    def supports(self, msg_id: int) -> bool:
        return msg_id in self.intervals

    def set_interval_us(self, msg_id: int, interval_us: float, now_s: float) -> bool:
        """MAV_CMD_SET_MESSAGE_INTERVAL: -1 off, 0 default, > 0 microseconds; False if refused."""
        if msg_id not in self.intervals or interval_us != interval_us:  # unknown id or NaN
            return False
        if interval_us == -1:
            self.intervals[msg_id] = None
        elif interval_us == 0:
            self.intervals[msg_id] = DEFAULT_INTERVALS[msg_id]
        elif interval_us > 0:
            self.intervals[msg_id] = interval_us * 1e-6
        else:
            return False
        self._due[msg_id] = now_s
        return True

    def interval_us(self, msg_id: int) -> int:
        """MESSAGE_INTERVAL's value: microseconds, -1 off, 0 not available."""
        if msg_id not in self.intervals:
            return 0
        iv = self.intervals[msg_id]
        return -1 if iv is None else int(round(iv * 1e6))

    def due(self, now_s: float) -> list[int]:
        """The streams to send at `now_s` (each once), scheduling their next times."""
        out = []
        for mid, iv in self.intervals.items():
            if iv is None or now_s + 1e-9 < self._due[mid]:
                continue
            out.append(mid)
            nxt = self._due[mid] + iv
            self._due[mid] = nxt if nxt > now_s else now_s + iv
        return out
