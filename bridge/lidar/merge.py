"""Several sensors as one LiDAR source: the newest complete sweep of each, de-skewed for the
boat's motion to the control time, moved into the body frame and merged; a sensor that falls
silent leaves the merge (and comes back), all silent too long is "perception lost".

`scan(t, pose)` keeps the bridge's interface (a body-frame (N, 3) cloud at the pose passed,
or None); `pop_notices()` gives what the bridge should say (console, log, STATUSTEXT) and
`lost(t)` the failsafe's reason, if any.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .deskew import deskew
from .mount import to_body

SEVERITY_WARNING, SEVERITY_INFO = 4, 6
MALFORMED_NOTE_EVERY_S = 5.0


@dataclass
class _Track:
    """What the merge knows about one sensor."""

    sensor: object
    mount: tuple
    role: str
    scan: object = None  # the newest SensorScan
    last_new_s: float | None = None  # bridge time its newest sweep came
    silent: bool = False
    malformed_said: int = 0
    malformed_said_at: float = -1e9


class MergedLidar:
    """The bridge's LiDAR source over sensors (see module doc). Each sensor has `name`,
    `spec`, `poll(t)` -> SensorScan | None, `malformed` and `close()`."""

    def __init__(self, sensors, mounts, roles=None, silent_after_s: float = 0.3,
                 lost_after_s: float = 1.0, deskew_on: bool = True):
        roles = roles or ["front"] * len(sensors)
        self.tracks = [_Track(s, tuple(m), r) for s, m, r in zip(sensors, mounts, roles)]
        self.silent_after_s, self.lost_after_s = float(silent_after_s), float(lost_after_s)
        self.deskew_on = deskew_on
        self.notices: list[tuple[str, int]] = []
        self.last_scan_s: float | None = None  # newest sweep's time among the merged ones
        self._all_silent_since: float | None = 0.0
        recorded = [t.sensor for t in self.tracks if getattr(t.sensor, "recorded", False)]
        firsts = [f for f in (s.first_time_s() for s in recorded) if f is not None]
        for s in recorded:  # sensors recorded together play together
            s.origin_s = min(firsts) if firsts else 0.0

    @property
    def name(self) -> str:
        return "+".join(t.sensor.spec for t in self.tracks)

    @property
    def viewpoints(self) -> tuple:
        """(x_m, y_m, height_m) of each sensor in the body frame (z down: height = -z_m):
        where the tracker judges free space from."""
        return tuple((float(t.mount[0]), float(t.mount[1]), -float(t.mount[2]))
                     for t in self.tracks)

    def scan(self, time_s: float, pose) -> np.ndarray | None:
        t = float(time_s)
        pose = np.asarray(pose, float).reshape(-1)
        velocity = pose[3:6] if len(pose) >= 6 else np.zeros(3)
        clouds = []
        for tr in self.tracks:
            got = tr.sensor.poll(t)
            if got is not None:
                tr.scan, tr.last_new_s = got, t
            self._health(tr, t)
            if tr.silent or tr.scan is None:
                continue
            pts = to_body(tr.scan.points, tr.mount)
            if self.deskew_on:
                times = tr.scan.times_s
                times = np.full(len(pts), tr.scan.stamp_s) if times is None else times
                pts = deskew(pts, times, t, velocity)
            clouds.append(pts)
        live = [tr for tr in self.tracks if not tr.silent and tr.scan is not None]
        if live:
            self.last_scan_s = max(tr.scan.stamp_s for tr in live)
            self._all_silent_since = None
        elif self._all_silent_since is None:  # since the newest sweep of any sensor
            self._all_silent_since = max(tr.last_new_s or 0.0 for tr in self.tracks)
        if not clouds:
            return None
        return np.concatenate(clouds) if len(clouds) > 1 else clouds[0]

    def _health(self, tr: _Track, t: float) -> None:
        quiet = t - (tr.last_new_s if tr.last_new_s is not None else 0.0)
        label = f"lidar {tr.sensor.name!r} ({tr.sensor.spec})"
        if not tr.silent and quiet > self.silent_after_s + 1e-9 and (tr.scan is not None or t > self.silent_after_s):
            tr.silent = True
            others = len([x for x in self.tracks if not x.silent])
            self.notices.append((f"{label} silent for {quiet:.1f} s: left out of the merge"
                                 f" ({others} of {len(self.tracks)} sensors merged)",
                                 SEVERITY_WARNING))
        elif tr.silent and quiet <= self.silent_after_s and tr.scan is not None:
            tr.silent = False
            self.notices.append((f"{label} is back: merged again", SEVERITY_INFO))
        bad = int(getattr(tr.sensor, "malformed", 0))
        if bad > tr.malformed_said and t - tr.malformed_said_at >= MALFORMED_NOTE_EVERY_S:
            self.notices.append((f"{label}: {bad - tr.malformed_said} malformed packets or "
                                 f"messages skipped ({bad} so far)", SEVERITY_WARNING))
            tr.malformed_said, tr.malformed_said_at = bad, t

    def lost(self, time_s: float) -> str | None:
        """The failsafe's reason when every sensor has been silent `lost_after_s`, else None."""
        since = self._all_silent_since
        if since is None or float(time_s) - since < self.lost_after_s - 1e-9:
            return None
        return (f"perception lost: no LiDAR sweep for {float(time_s) - since:.1f} s "
                f"({', '.join(tr.sensor.name for tr in self.tracks)} silent)")

    @property
    def malformed(self) -> dict[str, int]:
        return {tr.sensor.name: int(getattr(tr.sensor, "malformed", 0)) for tr in self.tracks}

    def pop_notices(self) -> list[tuple[str, int]]:
        out, self.notices = self.notices, []
        return out

    def close(self) -> None:
        for tr in self.tracks:
            tr.sensor.close()
