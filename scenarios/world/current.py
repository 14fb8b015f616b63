"""The water current over the canal: one constant current, or one that changes along it
(a side inflow, a lock's outflow) as a profile over the centre line's arc length."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.errors import InputError
from controller.geometry import Polyline


@dataclass(frozen=True, eq=False)
class CurrentField:
    """`profile` rows (s_m, north_mps, east_mps), linear in between and held past the ends,
    measured along `centre_line`; with no profile, `constant` everywhere."""

    constant: tuple[float, float] = (0.0, 0.0)
    profile: np.ndarray | None = None
    centre_line: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.profile is None:
            return
        prof = np.asarray(self.profile, float)
        if prof.ndim != 2 or prof.shape[1] != 3 or len(prof) < 1 or not np.isfinite(prof).all():
            raise InputError("current profile: expected [s_m, north_mps, east_mps] rows")
        if np.any(np.diff(prof[:, 0]) <= 0):
            raise InputError("current profile: the s_m values must increase")
        if self.centre_line is None:
            raise InputError("current profile: needs the canal's centre line to measure s along")
        object.__setattr__(self, "profile", prof)
        object.__setattr__(self, "_line", Polyline(np.asarray(self.centre_line, float)))

    @property
    def varies(self) -> bool:
        return self.profile is not None

    def at(self, xy) -> np.ndarray:
        """The current (north, east) in m/s where the boat is."""
        if self.profile is None:
            return np.asarray(self.constant, float)
        s = self._line.project(np.asarray(xy, float)[:2])[0]
        prof = self.profile
        return np.array([np.interp(s, prof[:, 0], prof[:, 1]), np.interp(s, prof[:, 0], prof[:, 2])])
