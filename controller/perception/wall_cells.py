"""Where walls have been seen: a memory of inertial grid cells for the tracker.

A quay seen close up gives long segments, and its returns are taken for wall. The same quay
seen later from 50 m, at a glancing angle or round a bend, comes back as a thin scatter that
neither makes a long segment nor lies on one straight line of one: each piece became a
cluster and a static "vessel" for seconds (29 such tracks in the Pohang run). So the cells
where returns of confident walls fell (segments or chains longer than any vessel, not the
pieces the memory itself made walls: it cannot feed on its own mistakes) are remembered for
`memory_s`, and a cluster whose points lie mostly in those cells (or next to them) is wall.
A vessel is never where a wall was; one moored alongside a quay keeps most of its points
off the quay's cells. Any shape of wall is covered, bends and curved quays included.

The cells are int64 keys in one sorted array with the time each was last seen; a scan adds
its wall cells (a few hundred unique ones) at most every `every_s`, which keeps the merge
off most scans.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_OFFSET = np.int64(1 << 30)  # cells up to 2^30 either side of the origin (5e8 m at 0.5 m)
_NEIGHBOURS = np.array([(di << 32) + dj for di in (-1, 0, 1) for dj in (-1, 0, 1)], np.int64)


@dataclass(frozen=True)
class WallCells:
    """The remembered cells: sorted keys, the time each was last seen, and when the memory
    last took a scan's cells."""

    keys: np.ndarray
    seen_s: np.ndarray
    updated_s: float = -np.inf

    @classmethod
    def empty(cls) -> "WallCells":
        return cls(np.zeros(0, np.int64), np.zeros(0))

    def __len__(self) -> int:
        return len(self.keys)


def cell_keys(xy: np.ndarray, cell_m: float) -> np.ndarray:
    """(N,) int64 keys of the cells of inertial points (N, 2)."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    i = np.floor(xy[:, 0] / cell_m).astype(np.int64) + _OFFSET
    j = np.floor(xy[:, 1] / cell_m).astype(np.int64) + _OFFSET
    return (i << 32) + j


def remember(memory: WallCells, wall_xy: np.ndarray, time_s: float, cell_m: float,
             memory_s: float) -> WallCells:
    """The memory with the cells of wall points `wall_xy` (inertial) seen at `time_s`, cells
    unseen for `memory_s` forgotten."""
    new = np.unique(cell_keys(wall_xy, cell_m))
    fresh = memory.seen_s >= time_s - memory_s
    old = memory.keys[fresh]
    keep = ~np.isin(old, new, assume_unique=True)
    keys = np.concatenate([old[keep], new])
    seen = np.concatenate([memory.seen_s[fresh][keep], np.full(len(new), float(time_s))])
    order = np.argsort(keys, kind="stable")
    return WallCells(keys[order], seen[order], float(time_s))


def due(memory: WallCells, time_s: float, every_s: float) -> bool:
    """Whether the memory should take this scan's wall cells."""
    return time_s - memory.updated_s >= every_s - 1e-9


def fraction_on(memory: WallCells, xy: np.ndarray, cell_m: float) -> float:
    """The share of inertial points (N, 2) lying in a remembered cell or next to one (0 for
    no points or an empty memory)."""
    if not len(memory) or not len(xy):
        return 0.0
    keys = (cell_keys(xy, cell_m)[:, None] + _NEIGHBOURS).ravel()
    at = np.minimum(np.searchsorted(memory.keys, keys), len(memory.keys) - 1)
    hit = (memory.keys[at] == keys).reshape(-1, len(_NEIGHBOURS)).any(axis=1)
    return float(np.count_nonzero(hit)) / len(hit)
