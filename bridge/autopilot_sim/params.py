"""The simulated autopilot's parameter table: ArduPilot Rover names, defaults, overrides.

Names are those of ArduPilot 4.7 (`MAV_GCS_SYSID`, `ARMING_SKIPCHK`) or, with `legacy`,
those of 4.5 and earlier (`SYSID_MYGCS`, `ARMING_CHECK`). Every value is a float (MAVLink
sends them all as REAL32); the index of a parameter is its place in name order, fixed for
the life of the table, as PARAM_VALUE's param_index needs.
"""

from __future__ import annotations

import math

from controller.errors import InputError, finite_number

from bridge.shared import ardupilot

NAME_LEN = 16  # PARAM_VALUE.param_id is 16 characters, not NUL-terminated when full


def default_params(system_id: int, legacy: bool) -> dict[str, float]:
    """ArduPilot's defaults for the parameters we simulate, with the names of one firmware era."""
    table = dict(ardupilot.DEFAULT_PARAMS)
    table["SYSID_THISMAV"] = float(system_id)
    if legacy:
        for old, new in ardupilot.PARAM_ALIASES.values():
            table.pop(new, None)
            table[old] = ardupilot.LEGACY_DEFAULTS[old]
    return table


class ParamTable:
    """Name -> float with stable indices; unknown names are refused, never added.

    `stored` holds the names given a value (at construction or by PARAM_SET), as if saved to
    the autopilot's storage: start-up defaults (`boot`, `finish_init`) never change those.
    """

    def __init__(self, system_id: int = 1, legacy: bool = False, overrides: dict | None = None):
        self.legacy = legacy
        self.values = default_params(system_id, legacy)
        self.defaults = dict(self.values)  # as PARM logs them beside the value
        self.stored: set[str] = set()
        for name, value in (overrides or {}).items():
            if name not in self.values:
                raise InputError(self._unknown(name))
            v = _number(name, value)
            self.values[name] = v
            self.stored.add(name)
        self.names = sorted(self.values)
        self._index = {n: i for i, n in enumerate(self.names)}
        self.boot()

    def _dead_zones(self) -> list[str]:
        """RCn_DZ of the steering and throttle channels (RCMAP_ROLL, RCMAP_THROTTLE)."""
        out = []
        for key in ("RCMAP_ROLL", "RCMAP_THROTTLE"):
            name = f"RC{int(self.values.get(key, 0))}_DZ"
            if name in self.values:
                out.append(name)
        return out

    def boot(self) -> None:
        """Values as start-up reads them: the dead zones not stored are RC_Channel's 0."""
        for name in self._dead_zones():
            if name not in self.stored:
                self.values[name] = 0.0

    def finish_init(self) -> list[str]:
        """Rover's late start-up defaults (`Rover::init_rc_in`): the steering and throttle
        dead zones not stored become 30 us. Returns the names that changed."""
        changed = []
        for name in self._dead_zones():
            if name not in self.stored and self.values[name] != ardupilot.ROVER_INIT_DEAD_ZONE_US:
                self.values[name] = ardupilot.ROVER_INIT_DEAD_ZONE_US
                changed.append(name)
        return changed

    def _unknown(self, name: str) -> str:
        other = {o: n for o, n in ardupilot.PARAM_ALIASES.values()}
        other.update({n: o for o, n in ardupilot.PARAM_ALIASES.values()})
        hint = ""
        if name in other:
            hint = (f"; this firmware calls it {other[name]}" +
                    ("" if self.legacy else " (or use the legacy parameter names)"))
        return f"unknown autopilot parameter {name!r}{hint}"

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def get(self, name: str, default: float | None = None) -> float | None:
        return self.values.get(name, default)

    def index(self, name: str) -> int | None:
        return self._index.get(name)

    def by_index(self, i: int) -> str | None:
        return self.names[i] if 0 <= i < len(self.names) else None

    def set(self, name: str, value: float) -> bool:
        """Set a known parameter to a finite value; False (nothing changes) otherwise."""
        if name not in self.values or not math.isfinite(value):
            return False
        self.values[name] = float(value)
        self.stored.add(name)
        return True

    # -- what the simulated firmware reads ----------------------------------------------
    @property
    def gcs_sysid(self) -> int:
        old, new = ardupilot.PARAM_ALIASES["gcs_sysid"]
        return int(self.values[old if self.legacy else new])

    def position_check_enabled(self) -> bool:
        """Whether arming waits for the EKF's position (Rover's AHRS check, GPS bit)."""
        old, new = ardupilot.PARAM_ALIASES["arming_check"]
        if self.legacy:  # checks to do: bit 0 is all of them
            mask = int(self.values[old])
            return bool(mask & (ardupilot.ARMING_CHECK_ALL | ardupilot.ARMING_CHECK_GPS))
        mask = int(self.values[new])  # checks to skip: -1 has every bit
        return not mask & ardupilot.ARMING_CHECK_GPS


def _number(name: str, value) -> float:
    return finite_number(value, f"autopilot parameter {name}")


def param_id(raw) -> str:
    """PARAM_* param_id as text (pymavlink gives str or bytes, NUL padded)."""
    if isinstance(raw, (bytes, bytearray)):
        raw = raw.decode("ascii", "replace")
    return str(raw).split("\x00", 1)[0]
