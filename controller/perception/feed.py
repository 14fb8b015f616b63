"""What perception hands the controller each control period: the cleaned segments of the
newest scan, or the last good ones for a short while when a scan is missing, or "blind".

A scan can be missing (a driver hiccup, a dropped packet train) or empty (no returns at
all, which a working LiDAR on a boat never delivers: it always sees its own hull and the
water). For up to `max_age_s` the previous segments stand in, so one lost scan changes
nothing; after that the controller is told it is blind and must slow to a stop, as before a
blocked way (the NMPC does), until scans come back. The last segments stay its constraints
meanwhile: they are in the inertial frame, so they still mark where the walls were.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .cleaning import DROP_REASONS, CleaningConfig, clean_segments


@dataclass(frozen=True)
class FeedConfig:
    """max_age_s: how long the last good segments stand in for missing scans (s)."""

    max_age_s: float = 1.0
    cleaning: CleaningConfig = field(default_factory=CleaningConfig)

    def __post_init__(self) -> None:
        v = self.max_age_s
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise InputError(f"perception feed: max_age_s must be a number >= 0, got {v!r}")


@dataclass(frozen=True)
class Percept:
    """What one scan gave: the static wall segments and the tracks of other vessels."""

    segments: np.ndarray  # (M, 4) rows (x_c, y_c, theta, length)
    tracks: tuple = ()  # perception.tracking.Track (or the truth in the same form)


@dataclass(frozen=True)
class PerceptionView:
    """One period's segments and vessel tracks for the controller, and how they came about."""

    segments: np.ndarray  # (M, 4) rows (x_c, y_c, theta, length), cleaned
    fresh: bool  # they come from a scan delivered this period
    age_s: float  # time since the scan they come from was delivered (inf: never a scan)
    blind: bool  # no usable scan for longer than max_age_s: slow to a stop
    dropped: dict  # rows cleaned away this period, by reason (cleaning.DROP_REASONS)
    tracks: tuple = ()  # vessel tracks, carried forward at their velocity over `age_s`


class SegmentFeed:
    """Cleans each period's detections and bridges short gaps between scans."""

    def __init__(self, config: FeedConfig = FeedConfig()):
        self.config = config
        self._last = np.zeros((0, 4))
        self._last_tracks: tuple = ()
        self._last_time: float | None = None
        self.dropped_total = dict.fromkeys(DROP_REASONS, 0)  # over the run
        self.missing_scans = 0  # periods with no usable scan
        self.blind_periods = 0

    def update(self, time_s: float, segments, position=None) -> PerceptionView:
        """This period's view. `segments`: the detections of a scan just delivered (an (M, 4)
        array, or a `Percept` with vessel tracks), or None when there was no scan (missing or
        empty). `position` (x, y) for the range check."""
        tracks = None
        if isinstance(segments, Percept):
            segments, tracks = segments.segments, tuple(segments.tracks)
        if segments is None:
            cleaned, dropped = None, dict.fromkeys(DROP_REASONS, 0)
        else:
            result = clean_segments(segments, position, self.config.cleaning)
            dropped = result.dropped
            cleaned = None if dropped["malformed"] else result.segments
        for k, n in dropped.items():
            self.dropped_total[k] += n
        if cleaned is not None:
            self._last, self._last_time = cleaned, float(time_s)
            self._last_tracks = tracks if tracks is not None else ()
            return PerceptionView(cleaned, True, 0.0, False, dropped, self._last_tracks)
        self.missing_scans += 1
        age = math.inf if self._last_time is None else float(time_s) - self._last_time
        blind = age > self.config.max_age_s
        self.blind_periods += blind
        # The last segments stay the constraints even when blind: they are in the inertial
        # frame, so they still mark where the walls were while the boat slows down. Vessels
        # move on: their tracks are carried forward at their velocity.
        tracks = tuple(_carried(tr, age) for tr in self._last_tracks) if math.isfinite(age) else ()
        return PerceptionView(self._last, False, age, blind, dropped, tracks)


def _carried(track, age_s: float):
    """A track moved on at its velocity over `age_s` (a dataclass: `dataclasses.replace`)."""
    from dataclasses import replace

    p = np.asarray(track.position, float) + age_s * np.asarray(track.velocity, float)
    return replace(track, position=p)
