"""Identification runs found in (or cut from) a long log: steady throttle steps, zigzags.

A boat's own log holds everything it did; identification wants the manoeuvres. Found
automatically from the commands:
- a *surge run* is a stretch of straight running ahead (|nS| <= 1 % and nT >= 0 throughout:
  reverse thrust, braking, is not the propeller the surge model describes; from `SETTLE_S`
  after the last turn so that sway and yaw have died out) with at least one throttle step of
  `MIN_STEP_PCT` or more and `MIN_SURGE_S` long; tagged acceleration or deceleration by the
  direction of its first step (surge when it goes both ways);
- a *zigzag* is a train of at least `MIN_REVERSALS` + 1 steering blocks (|nS| >= 5 %) of
  alternating sign, each change of side within `MAX_CROSSING_S`, at steady throttle (within
  `MAX_THROTTLE_SPREAD_PCT`); the run starts `LEAD_S` before the first block and ends
  `TAIL_S` after the last (or when the next command change comes). The commands must be
  known throughout; a short stretch without state (a gap in the log, at most
  `MAX_MISSING_S`) stays in the run, not measured there.
Or cut by hand, `Window(t0, t1)`, in the log's own time (seconds since boot, as ArduPilot's
log viewers show it), kind from the content.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .dataflash import FlightLog
from .logs import ManeuverLog

STRAIGHT_PCT = 1.0
MIN_STEP_PCT = 2.0
MIN_SURGE_S = 20.0
SETTLE_S = 10.0
TURNING_PCT = 5.0
MIN_REVERSALS = 2
MAX_CROSSING_S = 5.0
MAX_THROTTLE_SPREAD_PCT = 2.0
LEAD_S = 5.0
TAIL_S = 5.0
MAX_MISSING_S = 3.0


@dataclass(frozen=True)
class Window:
    """A stretch of a log to identify from, seconds of the log's own time."""

    t0: float
    t1: float
    use: str = "fit"  # or "heldout"

    @classmethod
    def parse(cls, text: str, use: str = "fit") -> "Window":
        """`T0:T1` (seconds since boot)."""
        a, sep, b = str(text).partition(":")
        try:
            if not sep:
                raise ValueError
            t0, t1 = float(a), float(b)
        except ValueError:
            raise InputError(f"window {text!r}: expected T0:T1 in seconds, e.g. 120:480") from None
        if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
            raise InputError(f"window {text!r}: need T0 < T1")
        return cls(t0, t1, use)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index pairs of the True stretches of `mask`."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return list(zip(edges[::2], edges[1::2]))


def _usable(log: FlightLog) -> np.ndarray:
    return np.all(np.isfinite(log.commands), axis=1) & np.isfinite(log.states[:, 3])


def _longest_missing(measured: np.ndarray) -> int:
    """Samples in the longest stretch of `measured` False."""
    return max((b - a for a, b in _runs(~measured)), default=0)


def _surge_runs(log: FlightLog) -> list[tuple[int, int, str]]:
    t, nT, nS = log.time_s, log.commands[:, 0], log.commands[:, 1]
    dt = float(np.median(np.diff(t)))
    out = []
    straight = _usable(log) & (np.abs(nS) <= STRAIGHT_PCT) & (nT >= 0.0)
    turning = np.flatnonzero(~(np.abs(nS) <= STRAIGHT_PCT))  # (NaN counts as turning)
    settle = int(round(SETTLE_S / dt))
    for a, b in _runs(straight):
        # SETTLE_S after the last turn, so that sway and yaw have died out (a stretch of
        # reverse thrust between, braking straight ahead, counts toward it)
        before = turning[turning < a]
        if before.size:
            a = min(b, max(a, int(before[-1]) + 1 + settle))
        if (b - a) * dt < MIN_SURGE_S:
            continue
        levels = nT[a:b]
        steps = np.diff(levels)
        big = np.flatnonzero(np.abs(steps) >= 0.05)  # moving: ramps count as steps
        if np.ptp(levels) < MIN_STEP_PCT or not big.size:
            continue
        ups, downs = np.sum(steps[steps > 0]), -np.sum(steps[steps < 0])
        first = steps[big[0]]
        if ups >= MIN_STEP_PCT and downs >= MIN_STEP_PCT:
            kind = "acceleration" if first > 0 else "deceleration"
            kind = "surge" if min(ups, downs) > 0.25 * max(ups, downs) else kind
        else:
            kind = "acceleration" if ups > downs else "deceleration"
        out.append((a, b, kind))
    return out


def _zigzags(log: FlightLog) -> list[tuple[int, int, str]]:
    t, nT, nS = log.time_s, log.commands[:, 0], log.commands[:, 1]
    dt = float(np.median(np.diff(t)))
    usable = _usable(log)
    side = np.where(nS >= TURNING_PCT, 1, np.where(nS <= -TURNING_PCT, -1, 0))
    blocks = [(a, b, int(side[a])) for a, b in _runs(side != 0)]
    out, k = [], 0
    while k < len(blocks):
        train = [blocks[k]]
        level = float(np.median(nT[blocks[k][0]:blocks[k][1]]))
        while k + 1 < len(blocks):
            nxt = blocks[k + 1]
            gap_s = (nxt[0] - train[-1][1]) * dt
            head = nT[nxt[0]:max(nxt[0] + 1, (nxt[0] + nxt[1]) // 2)]  # the run may end in it
            same_throttle = np.all(np.abs(head - level) <= MAX_THROTTLE_SPREAD_PCT)
            if nxt[2] == -train[-1][2] and gap_s <= MAX_CROSSING_S and same_throttle:
                train.append(nxt)
                k += 1
            else:
                break
        k += 1
        if len(train) < MIN_REVERSALS + 1:
            continue
        first, last = train[0][0], train[-1][1]
        away = np.flatnonzero(np.abs(nT[first:last] - level) > MAX_THROTTLE_SPREAD_PCT)
        if away.size:  # the throttle left the zigzag's level: the run ended there
            last = first + int(away[0])
        commanded = np.all(np.isfinite(log.commands[first:last]), axis=1)
        if (last <= train[-2][1] or not commanded.all()
                or _longest_missing(usable[first:last]) * dt > MAX_MISSING_S):
            continue
        # the lead-in and the tail: straight, at the same throttle, at most LEAD_S / TAIL_S

        def calm(i):
            return (usable[i] and abs(nS[i]) < TURNING_PCT
                    and abs(nT[i] - level) <= MAX_THROTTLE_SPREAD_PCT)

        a = first
        while a > 0 and first - a < LEAD_S / dt and calm(a - 1):
            a -= 1
        b = last
        while b < len(t) and b - last < TAIL_S / dt and calm(b):
            b += 1
        out.append((a, b, "zigzag"))
    return out


def _piece(log: FlightLog, a: int, b: int, kind: str, use: str, how: str) -> ManeuverLog:
    t = log.time_s[a:b]
    applied = log.commands[a:max(b - 1, a + 1)]  # the last sample's command comes after it
    meta = {
        "maneuver": kind, "use": use,
        "description": f"{kind} {how} in {log.source} at t = {t[0]:.1f}-{t[-1]:.1f} s "
                       f"(nT {np.nanmin(applied[:, 0]):.1f}-{np.nanmax(applied[:, 0]):.1f} %, "
                       f"|nS| up to {np.nanmax(np.abs(applied[:, 1])):.1f} %)",
        "window": f"{t[0]:.1f}:{t[-1]:.1f}",
        **{f"source.{k}": v for k, v in log.sources.items()},
    }
    return ManeuverLog(t.copy(), log.states[a:b].copy(), log.commands[a:b].copy(), meta,
                       source=f"{log.source}@{t[0]:.1f}-{t[-1]:.1f}s")


def find_runs(log: FlightLog) -> list[ManeuverLog]:
    """The surge runs and zigzags in `log`, in time order (see the module docstring)."""
    pieces = sorted(_surge_runs(log) + _zigzags(log))
    return [_piece(log, a, b, kind, "fit", "found") for a, b, kind in pieces]


def cut_windows(log: FlightLog, windows) -> list[ManeuverLog]:
    """The given windows of `log` (InputError names a window outside it or without data)."""
    out = []
    for w in windows:
        sel = np.flatnonzero((log.time_s >= w.t0) & (log.time_s <= w.t1))
        if sel.size < 2:
            raise InputError(f"{log.source}: window {w.t0:g}:{w.t1:g} s holds no samples (the "
                             f"log runs from {log.time_s[0]:.1f} to {log.time_s[-1]:.1f} s)")
        a, b = int(sel[0]), int(sel[-1]) + 1
        bad = ~np.all(np.isfinite(log.commands[a:b]), axis=1)
        if bad.all():
            raise InputError(f"{log.source}: window {w.t0:g}:{w.t1:g} s: no commands there")
        # the kind from the commands applied within the window: the last sample's is the
        # one after it (what the boat did next), never used in the fit
        applied = log.commands[a:max(b - 1, a + 1), 1]
        kind = "surge" if np.nanmax(np.abs(applied)) <= STRAIGHT_PCT else "sway-yaw"
        keep = np.flatnonzero(~bad)
        out.append(_piece(log, a + int(keep[0]), a + int(keep[-1]) + 1, kind, w.use, "selected"))
    return out
