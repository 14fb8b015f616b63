"""Is the way ahead open? Where the segments leave no passage for the hull, the boat stops.

A barge across the canal, a closed lock gate, a false wall from a bad scan: the route then
runs through something, and no plan can follow it. Asking the NMPC to, as before, makes its
QP infeasible while the boat is still at speed; a blocked way is not a solver failure but a
reason to slow down, stop short and wait. So before each solve the segments are put into the
route's own coordinates (arc length s along the waypoint path, offset d across it) and swept
in slabs `slab_m` long: in each slab the offsets the segments occupy split the cross-section
into free intervals; an interval at least `min_passage_m` wide that shares half of that with
one reachable in the slab before is reachable. The way is blocked at the first slab with none.

The rule, and why: the passage must be as wide as the two hull circles (2 R_b = 6 m by
default), the room the NMPC needs to pass with all of its separation d_p given up to the
slack; a gap narrower than that (a 2.5 m side channel beside a bridge pier) is not a way for
this boat, while the narrow stretches it is built for (8.5 m, 9 m between piers) are.
Reachability from slab to slab lets the boat weave between staggered obstacles; a wall
missing from the scan only ever makes the way look more open, so detection gaps never stop
the boat, they leave it to the NMPC as before.

`WayAhead` adds the time: a sweep every `sweep_every_s` (0.5 s, a metre at 2 m/s), blocked at
once, clear again only after `resume_after_s` of clear sweeps (a missed scan does not
restart the boat), and blind (no usable scans) is a stop too, at the braking distance from
where the boat was when it went blind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kernels import pointer
from .path_geometry import geometry_kernel
from .reference import WaypointPath


@dataclass(frozen=True)
class Stop:
    """Where the reference must stop (arc length along the path) and why."""

    at_m: float  # the boat's origin stops here
    reason: str  # "way blocked at 23 m" | "blind: no usable scan"
    blocked_at_m: float | None = None  # arc length of the obstruction, if blocked


def waiting_kind(reason: str) -> str:
    """What a `Stop.reason` is about, without its distance: "way blocked", "blind" or ""
    (so a hold is announced once, not again each time the distance changes)."""
    return reason.split(" at ")[0].split(":")[0]


@dataclass(frozen=True)
class Channel:
    """Where the way open ahead lies off the path: from arc length `start_m[k]` for `slab_m`,
    the boat's line must be `offset_m[k]` across the path (+ to starboard) to pass with the
    room it needs; elsewhere the path itself is open."""

    start_m: np.ndarray
    offset_m: np.ndarray
    slab_m: float = 1.0

    def __bool__(self) -> bool:
        return bool(len(self.start_m))

    def at(self, s, ramp_m: float) -> np.ndarray:
        """The offset (n,) at arc lengths s: each slab's, faded out linearly over `ramp_m`
        before and after it (so the boat moves over before the gap, and back after), the
        largest in size where two overlap."""
        s = np.atleast_1d(np.asarray(s, float))
        if not self:
            return np.zeros(len(s))
        lo, hi = self.start_m, self.start_m + self.slab_m
        gap = np.maximum(np.maximum(lo[None, :] - s[:, None], s[:, None] - hi[None, :]), 0.0)
        weight = np.clip(1.0 - gap / ramp_m, 0.0, 1.0)
        values = weight * self.offset_m[None, :]
        pick = np.argmax(np.abs(values), axis=1)
        return values[np.arange(len(s)), pick]


NO_CHANNEL = Channel(np.zeros(0), np.zeros(0))


def blocked_at(path: WaypointPath, progress_m: float, offset_m: float, segments,
               min_passage_m: float, lookahead_m: float, lateral_m: float = 30.0,
               slab_m: float = 1.0, spacing_m: float = 0.5) -> float | None:
    """Arc length of the first slab ahead of `progress_m` (within `lookahead_m`) where the
    segments leave no passage at least `min_passage_m` wide that connects back to the boat
    (at `offset_m` across the path), or None when the way is open."""
    return sweep(path, progress_m, offset_m, segments, min_passage_m, lookahead_m, lateral_m,
                 slab_m, spacing_m)[0]


def sweep(path: WaypointPath, progress_m: float, offset_m: float, segments,
          min_passage_m: float, lookahead_m: float, lateral_m: float = 30.0,
          slab_m: float = 1.0, spacing_m: float = 0.5, clearance_m: float | None = None):
    """`blocked_at`, and the `Channel` the boat must take where the passage it reaches lies
    off the path: in each slab before the blockage (or all of them), where the path's line
    does not have half a passage of room either side within the interval the boat reaches,
    the line is moved into that interval, `clearance_m` (default half the passage: the hull
    circle touching) from its sides where the interval is wide enough, else to its middle.
    The OCP keeps the hull circles as far out (`NmpcConfig.min_half_axis_m`), so what the
    sweep calls open the plan can pass, and at its speed."""
    segs = np.asarray(segments, float).reshape(-1, 4)
    s_end = min(progress_m + lookahead_m, path.length)
    if not len(segs) or s_end <= progress_m:
        return None, NO_CHANNEL
    # Only the parts near the way ahead: within reach of the path points from here to s_end.
    centre, _ = path.at(0.5 * (progress_m + s_end))
    a, b, length = _inside_circle(segs, centre[0], 0.5 * (s_end - progress_m) + lateral_m)
    if not len(a):
        return None, NO_CHANNEL
    n = np.maximum(np.ceil(length / spacing_m).astype(int), 1) + 1
    which = np.repeat(np.arange(len(a)), n)
    frac = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    pts = a[which] + frac[:, None] * (b - a)[which]
    s, d = path.frame(pts, progress_m - slab_m, s_end + slab_m)
    s, d = _continuous(s, d, which, slab_m)
    ahead = (s >= progress_m) & (s <= s_end) & (np.abs(d) <= lateral_m)
    if not ahead.any():
        return None, NO_CHANNEL
    slab = ((s[ahead] - progress_m) / slab_m).astype(np.int64)
    d = d[ahead]
    n_slabs = int(math.ceil((s_end - progress_m) / slab_m))
    order = np.lexsort((d, slab))
    slab, d = slab[order], d[order]
    # Two slabs' intervals connect when they share half a passage: a wall tilted against the
    # path moves its points a little from slab to slab, which must not connect the water
    # behind it, while a channel shifting sideways up to 3 m per slab still connects.
    overlap = 0.5 * min_passage_m
    keep = overlap if clearance_m is None else max(clearance_m, overlap)
    at, shifts = walk_slabs(slab, d, n_slabs, lateral_m, min_passage_m, overlap, keep,
                            offset_m)
    return (None if at is None else progress_m + at * slab_m), _channel(shifts, progress_m,
                                                                         slab_m)


def _continuous(s: np.ndarray, d: np.ndarray, which: np.ndarray, slab_m: float):
    """The samples' path coordinates (s, d) with points added where two neighbouring samples
    of one segment lie more than a slab apart along the path, evenly between them: a wall
    is continuous. Inside a bend the frame jumps from one leg to the next, and the inner
    wall's samples skip the slabs at the corner (2 |d| tan(turn / 2) of them: 4 m at 6 m off
    for 38 degrees), whose water then opened onto the bank behind the wall, and the sweep
    found a way round a kayak through it (fuzz seed 1 case 102)."""
    jump = np.flatnonzero((which[1:] == which[:-1]) & (np.abs(np.diff(s)) > slab_m))
    if not len(jump):
        return s, d
    pieces = np.ceil(np.abs(s[jump + 1] - s[jump]) / (0.5 * slab_m)).astype(np.int64)
    at = np.repeat(jump, pieces - 1)
    frac = (np.arange(int((pieces - 1).sum())) - np.repeat(np.cumsum(pieces - 1) - (pieces - 1),
                                                           pieces - 1) + 1) / np.repeat(pieces,
                                                                                        pieces - 1)
    return (np.concatenate([s, s[at] + frac * (s[at + 1] - s[at])]),
            np.concatenate([d, d[at] + frac * (d[at + 1] - d[at])]))


def walk_slabs(slab: np.ndarray, d: np.ndarray, n_slabs: int, lateral_m: float,
               min_passage_m: float, overlap: float, keep: float, offset_m: float):
    """The sweep's walk over slabs 0..n_slabs-1, given the points' slabs and offsets sorted
    by (slab, offset): the first slab no free interval of which (at least `min_passage_m`
    wide, between neighbouring points or a point and +-`lateral_m`) shares `overlap` with
    one reached in the slab before (the boat itself: `offset_m` +- `overlap`), or None; and
    the (slab, offset) shifts where the path's line has not the room it needs, into the
    reached interval nearest it (`keep` from its sides where wide enough, else its middle).
    By the kernel `path_geometry.c`, or `walk_slabs_numpy`."""
    lib = geometry_kernel()
    if lib is None:
        return walk_slabs_numpy(slab, d, n_slabs, lateral_m, min_passage_m, overlap, keep,
                                offset_m)
    slab = np.ascontiguousarray(slab, np.int64)
    d = np.ascontiguousarray(d, float)
    scratch = np.empty(4 * (len(d) + 2))
    shift_at, shift_d = np.empty(max(n_slabs, 1), np.int64), np.empty(max(n_slabs, 1))
    n_shifts = np.zeros(1, np.int64)
    at = lib.walk_slabs(len(d), pointer(slab), pointer(d), n_slabs, float(lateral_m),
                        float(min_passage_m), float(overlap), float(keep), float(offset_m),
                        pointer(scratch), pointer(shift_at), pointer(shift_d),
                        pointer(n_shifts))
    k = int(n_shifts[0])
    return (None if at < 0 else int(at)), list(zip(shift_at[:k].tolist(),
                                                   shift_d[:k].tolist()))


def walk_slabs_numpy(slab: np.ndarray, d: np.ndarray, n_slabs: int, lateral_m: float,
                     min_passage_m: float, overlap: float, keep: float, offset_m: float):
    """`walk_slabs`' twin in numpy and Python."""
    # Every free interval of every slab at once: between neighbours in a slab, and from the
    # edges of the lateral range to a slab's first and last point.
    first = np.r_[True, slab[1:] != slab[:-1]]
    last = np.r_[slab[1:] != slab[:-1], True]
    lo = np.concatenate([np.full(first.sum(), -lateral_m), d[:-1][~first[1:]], d[last]])
    hi = np.concatenate([d[first], d[1:][~first[1:]], np.full(last.sum(), lateral_m)])
    k = np.concatenate([slab[first], slab[1:][~first[1:]], slab[last]])
    wide = hi - lo >= min_passage_m
    k, lo, hi = k[wide], lo[wide], hi[wide]
    by_slab = np.lexsort((lo, k))
    k, lo, hi = k[by_slab], lo[by_slab].tolist(), hi[by_slab].tolist()
    first_gap = np.searchsorted(k, np.arange(n_slabs + 1)).tolist()  # slab j: [j], [j + 1]
    occupied = np.zeros(n_slabs + 1, bool)
    occupied[np.minimum(slab, n_slabs)] = True
    occupied = occupied.tolist()
    reach = [(offset_m - overlap, offset_m + overlap)]  # the boat itself
    shifts = []  # (slab, offset) where the path's line has not the room it needs
    for j in range(n_slabs):
        if not occupied[j]:
            reach = [(-lateral_m, lateral_m)]  # nothing in this slab: all of it is open
            continue
        reached = []
        for i in range(first_gap[j], first_gap[j + 1]):
            g0, g1 = lo[i], hi[i]
            for r0, r1 in reach:
                if min(g1, r1) - max(g0, r0) >= overlap:
                    reached.append((g0, g1))
                    break
        if not reached:
            return j, shifts
        reach = reached
        if not any(g0 <= -overlap and g1 >= overlap for g0, g1 in reached):
            # the line d = 0 is too close to something: into the reached interval nearest it
            targets = [((g0 + g1) / 2 if g1 - g0 < 2 * keep else min(max(0.0, g0 + keep), g1 - keep))
                       for g0, g1 in reached]
            shifts.append((j, min(targets, key=abs)))
    return None, shifts


def _channel(shifts, progress_m: float, slab_m: float) -> Channel:
    if not shifts:
        return NO_CHANNEL
    j, d = (np.array(v, float) for v in zip(*shifts))
    return Channel(progress_m + j * slab_m, d, slab_m)


def _inside_circle(segments: np.ndarray, centre: np.ndarray, radius_m: float):
    """The parts of (M, 4) segments inside a circle: their endpoints (K, 2) twice and lengths
    (K,) (`geometry.clip_segments_to_circle` without the round trip through (x_c, y_c,
    theta, length), a sweep's largest cost after the path frame)."""
    cos, sin = np.cos(segments[:, 2]), np.sin(segments[:, 2])
    h = 0.5 * segments[:, 3]
    ax, ay = segments[:, 0] - h * cos, segments[:, 1] - h * sin
    dx, dy = 2.0 * h * cos, 2.0 * h * sin
    fx, fy = ax - centre[0], ay - centre[1]
    dd = dx * dx + dy * dy
    bq = fx * dx + fy * dy
    disc = bq * bq - dd * (fx * fx + fy * fy - radius_m**2)
    root = np.sqrt(np.maximum(disc, 0.0))
    safe = np.where(dd > 0, dd, 1.0)
    t0 = np.minimum(np.maximum((-bq - root) / safe, 0.0), 1.0)
    t1 = np.minimum(np.maximum((-bq + root) / safe, 0.0), 1.0)
    keep = (disc > 0) & (t1 > t0)
    a = np.column_stack([ax + t0 * dx, ay + t0 * dy])[keep]
    b = np.column_stack([ax + t1 * dx, ay + t1 * dy])[keep]
    return a, b, (t1 - t0)[keep] * np.sqrt(dd[keep])


class WayAhead:
    """Blocked, blind or open, step by step, with the hysteresis a noisy scan needs."""

    def __init__(self, min_passage_m: float, stop_short_m: float, decel_mps2: float,
                 resume_after_s: float, sweep_every_s: float = 0.5,
                 clearance_m: float | None = None, reopen_m: float = 0.5):
        self.min_passage_m = min_passage_m
        # a way found blocked is open again only for a gap this much wider: a gap about the
        # hull's width, read a little wider or narrower by each scan, does not stop and start
        # the boat in turn (open while it approaches, blocked when it gets there)
        self.reopen_m = reopen_m
        self.clearance_m = clearance_m  # from a gap's sides to the boat's line (`sweep`)
        self.stop_short_m = stop_short_m  # from the obstruction to the boat's origin
        self.decel_mps2 = decel_mps2
        self.resume_after_s = resume_after_s
        self.sweep_every_s = sweep_every_s  # the sweep costs ~0.5 ms: twice a second will do
        self.reset()

    def reset(self) -> None:
        self._stop: Stop | None = None
        self._clear_s = 0.0
        self._blind_stop_m: float | None = None
        self._since_sweep = None  # s since the last sweep (None: sweep now)
        self.channel = NO_CHANNEL  # where the last sweep found the way off the path

    def memory(self) -> tuple:
        """What `update` moves on, to put back with `restore` (all of it immutable)."""
        return self._stop, self._clear_s, self._blind_stop_m, self._since_sweep, self.channel

    def restore(self, memory: tuple) -> None:
        (self._stop, self._clear_s, self._blind_stop_m, self._since_sweep,
         self.channel) = memory

    def update(self, path: WaypointPath, progress_m: float, offset_m: float, speed_mps: float,
               segments, blind: bool, period_s: float, lookahead_m: float) -> Stop | None:
        """The stop to make this period, or None to go on."""
        if blind:
            if self._blind_stop_m is None:  # brake from where the boat went blind
                self._blind_stop_m = progress_m + max(speed_mps, 0.0) ** 2 / (2 * self.decel_mps2)
            self._stop, self._clear_s = Stop(self._blind_stop_m, "blind: no usable scan"), 0.0
            return self._stop
        self._blind_stop_m = None
        if self._since_sweep is not None:
            self._since_sweep += period_s
            if self._since_sweep < self.sweep_every_s - 1e-9:
                return self._stop  # as at the last sweep (1 m at 2 m/s)
        elapsed, self._since_sweep = self._since_sweep or 0.0, 0.0
        widest = self.min_passage_m + (self.reopen_m if self._stop is not None else 0.0)
        at, self.channel = sweep(path, progress_m, offset_m, segments, widest,
                                 lookahead_m, clearance_m=self.clearance_m)
        if at is not None:
            self._clear_s = 0.0
            self._stop = Stop(at - self.stop_short_m, f"way blocked at {at - progress_m:.0f} m", at)
            return self._stop
        if self._stop is not None:
            self._clear_s += max(elapsed, period_s)
            if self._clear_s < self.resume_after_s - 1e-9:
                return self._stop  # hold on until the way has stayed clear a while
        self._stop, self._clear_s = None, 0.0
        return None
