"""A boat's own ArduPilot DataFlash log (.BIN) as identification data: state and commands.

Read with pymavlink's DFReader (pymavlink is a dependency of the package; it is imported
here only when a log is read). Where each quantity comes from, the first that the log has:

- position (north, east m): XKF1.PN/PE (the EKF's, from its origin; primary core), else
  POS.Lat/Lng, else GPS.Lat/Lng (with a 3D fix) around the first of them;
- NED velocity: XKF1.VN/VE, else GPS.Spd/GCrs, else the position differentiated;
- heading: XKF1.Yaw, else ATT.Yaw, else AHR2.Yaw;
- yaw rate: IMU.GyrZ less the EKF's gyro bias XKF1.GZ (the boat is level), else the heading
  differentiated;
- commands: the servo outputs RCOU mapped back to nT, nS with the SERVOn_FUNCTION and
  SERVOn_MIN/MAX/TRIM/REVERSED in force (PARM, followed through the log), else the RC inputs
  RCIN with RCMAP_* and RCn_* while armed in MANUAL (where Rover passes them straight out).

Everything is put on one time base (the position's, TimeUS), resampled every `sample_s`
(0.1 s by default, the paper's rate): states interpolated, commands averaged over each
interval (what was applied from one sample to the next). u, v are the NED velocity turned
into the body frame by the heading. Where the position source has a gap (longer than
`MAX_GAP_S`), the samples across it are "not measured". What the log lacks is an InputError
naming the message and the field.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..geodetic import geodetic_to_ned
from ..pwm import CommandChannels

MAX_GAP_S = 1.0
MESSAGES = ("PARM", "MODE", "ARM", "XKF1", "ATT", "AHR2", "POS", "GPS", "IMU", "RCOU", "RCIN")
MANUAL = 0  # Rover's mode number
GPS_3D_FIX = 3


@dataclass(frozen=True, eq=False)
class FlightLog:
    """A DataFlash log on a uniform time base: states [x, y, psi, u, v, r] (SI), commands
    [nT, nS] (percent, held to the next sample), NaN where unknown; `sources` says which
    message and field gave each quantity, `params` the parameters at the end of the log."""

    source: str
    time_s: np.ndarray  # TimeUS / 1e6
    states: np.ndarray  # (N, 6)
    commands: np.ndarray  # (N, 2)
    mode: np.ndarray  # (N,) Rover mode number (-1 unknown)
    armed: np.ndarray  # (N,) bool
    sources: Mapping[str, str] = field(default_factory=dict)
    params: Mapping[str, float] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    @property
    def n_samples(self) -> int:
        return len(self.time_s)


def is_dataflash(path: str | Path) -> bool:
    """True when the file starts with a DataFlash FMT record (0xA3 0x95 0x80)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(3) == b"\xa3\x95\x80"
    except OSError:
        return False


# -- reading the messages -------------------------------------------------------------------
@dataclass
class _Series:
    """One message type's records: TimeUS and the wanted fields, as arrays."""

    columns: tuple[str, ...]
    rows: list = field(default_factory=list)

    def array(self, name: str) -> np.ndarray:
        k = self.columns.index(name)
        return np.array([r[k] for r in self.rows], float)

    @property
    def time_s(self) -> np.ndarray:
        return self.array("TimeUS") * 1e-6


def _open(path: Path):
    try:
        from pymavlink import DFReader
    except ImportError as exc:  # pragma: no cover - pymavlink is a core dependency
        raise InputError(f"{path}: reading DataFlash logs needs pymavlink ({exc})") from None
    if not path.exists():
        raise InputError(f"{path}: no such log file")
    if not is_dataflash(path):
        raise InputError(f"{path}: not an ArduPilot DataFlash log (.BIN): it does not start "
                         "with a FMT record (bytes A3 95 80)")
    try:
        return DFReader.DFReader_binary(str(path))
    except Exception as exc:  # noqa: BLE001 - DFReader raises anything on a damaged file
        raise InputError(f"{path}: cannot read the DataFlash log ({exc})") from None


def _columns(reader) -> dict[str, tuple[str, ...]]:
    """name -> columns, from the log's own FMT records."""
    return {f.name: tuple(f.columns) for f in reader.formats.values()}


class _ServoConversion:
    """RCOU (or RCIN) records to (nT, nS) with the parameters in force at each record."""

    def __init__(self, kind: str, source: Path):
        self.kind, self.source = kind, source
        self.params: dict[str, float] = {}
        self._channels = None
        self._stale = True
        self.error: str | None = None

    def param(self, name: str, value: float) -> None:
        self.params[name] = value
        prefix = ("SERVO",) if self.kind == "RCOU" else ("RC", "RCMAP_")
        if name.startswith(prefix):
            self._stale = True

    def channels(self):
        if self._stale:
            self._stale = False
            try:
                self._channels = (CommandChannels.from_servo_params(self.params)
                                  if self.kind == "RCOU" else
                                  CommandChannels.from_rc_params(self.params))
                self.error = None
            except ValueError as exc:
                self._channels, self.error = None, str(exc)
        return self._channels


def _read_messages(path: Path):
    """Every record of MESSAGES in time order (the servo commands converted as they come)."""
    reader = _open(path)
    try:
        columns = _columns(reader)
        series = {name: _Series(columns[name]) for name in MESSAGES
                  if name in columns and name not in ("PARM", "RCOU", "RCIN")}
        params: dict[str, float] = {}
        servo = {k: _ServoConversion(k, path) for k in ("RCOU", "RCIN")}
        commands = {"RCOU": [], "RCIN": []}  # (t, nT, nS)
        errors = {}
        last_us = 0
        while (m := reader.recv_match(type=list(MESSAGES))) is not None:
            last_us = max(last_us, int(getattr(m, "TimeUS", 0) or 0))
            kind = m.get_type()
            if kind == "PARM":
                name, value = str(m.Name), float(m.Value)
                params[name] = value
                for conv in servo.values():
                    conv.param(name, value)
            elif kind in commands:
                ch = servo[kind].channels()
                if ch is None:
                    errors[kind] = servo[kind].error
                    continue
                pwm = {c.channel: getattr(m, f"C{c.channel}", None) for c in (ch.steering, ch.throttle)}
                if any(v is None for v in pwm.values()):
                    errors[kind] = (f"message {kind} has no field C{max(pwm)} for the mapped "
                                    "channel (it logs 14)")
                    continue
                commands[kind].append((m.TimeUS * 1e-6, *ch.to_commands(pwm)))
            else:
                s = series[kind]
                s.rows.append(tuple(getattr(m, c, math.nan) for c in s.columns))
        left = int(reader.data_len - reader.offset)  # bytes no record could be read from
        if left >= 3:
            errors["truncated"] = (f"the log ends in the middle of a record ({left} bytes at "
                                   f"the end are no whole record): it was cut short, read up "
                                   f"to t = {last_us * 1e-6:.1f} s")
    finally:
        reader.close()
    return columns, series, params, commands, errors


# -- choosing the sources -------------------------------------------------------------------
def _need(columns, series, name: str, fields: tuple[str, ...]) -> str | None:
    """None when message `name` is in the log with `fields` and records; else why not."""
    if name not in columns:
        return f"{name} (not in the log)"
    missing = [f for f in fields if f not in columns[name]]
    if missing:
        return f"{name}.{'/'.join(missing)} (the log's {name} has no such field)"
    if not series.get(name) or not series[name].rows:
        return f"{name} (no records)"
    return None


def _primary_core(s: _Series) -> tuple[np.ndarray, int, int]:
    """Rows of the lowest EKF core (XKF1.C) and how many cores logged."""
    cores = s.array("C") if "C" in s.columns else np.zeros(len(s.rows))
    core = int(np.nanmin(cores))
    return cores == core, core, len(np.unique(cores))


def _unwrap_deg(deg: np.ndarray) -> np.ndarray:
    return np.unwrap(np.radians(deg))


def _derivative(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.gradient(y, t) if len(t) > 2 else np.zeros_like(y)


def _interp(t_new, t, y):
    """Linear interpolation; NaN outside the samples (beyond a microsecond's rounding)."""
    ok = np.isfinite(y)
    if ok.sum() < 2:
        return np.full(len(t_new), np.nan)
    t, y = t[ok], y[ok]
    out = np.interp(t_new, t, y)
    out[(t_new < t[0] - 1e-6) | (t_new > t[-1] + 1e-6)] = np.nan
    return out


def _position(columns, series, notes):
    """(time, north, east, source) of the best position source."""
    why = []
    reason = _need(columns, series, "XKF1", ("PN", "PE"))
    if reason is None:
        s = series["XKF1"]
        rows, core, n_cores = _primary_core(s)
        if n_cores > 1:
            notes.append(f"XKF1: {n_cores} EKF cores logged, core {core} used")
        return s.time_s[rows], s.array("PN")[rows], s.array("PE")[rows], f"XKF1.PN/PE (core {core})"
    why.append(reason)
    for name in ("POS", "GPS"):
        reason = _need(columns, series, name, ("Lat", "Lng"))
        if reason is None:
            s = series[name]
            lat, lon, t = s.array("Lat"), s.array("Lng"), s.time_s
            ok = np.isfinite(lat) & np.isfinite(lon) & ((lat != 0) | (lon != 0))
            if name == "GPS" and "Status" in s.columns:
                ok &= s.array("Status") >= GPS_3D_FIX
            if ok.sum() >= 2:
                first = (lat[ok][0], lon[ok][0])
                n, e = geodetic_to_ned(lat[ok], lon[ok], first)
                return t[ok], n, e, f"{name}.Lat/Lng (around its first point)"
            reason = f"{name}.Lat/Lng (no valid fix)"
        why.append(reason)
    raise InputError("no position: tried " + ", ".join(why))


def _velocity(columns, series, t, north, east, notes):
    reason = _need(columns, series, "XKF1", ("VN", "VE"))
    if reason is None:
        s = series["XKF1"]
        rows, _, _ = _primary_core(s)
        ts = s.time_s[rows]
        return (_interp(t, ts, s.array("VN")[rows]), _interp(t, ts, s.array("VE")[rows]),
                "XKF1.VN/VE")
    why = [reason]
    reason = _need(columns, series, "GPS", ("Spd", "GCrs"))
    if reason is None:
        s = series["GPS"]
        ok = s.array("Status") >= GPS_3D_FIX if "Status" in s.columns else np.ones(len(s.rows), bool)
        if ok.sum() >= 2:
            spd, crs, ts = s.array("Spd")[ok], np.radians(s.array("GCrs")[ok]), s.time_s[ok]
            notes.append(f"velocity from GPS.Spd/GCrs ({'; '.join(why)} missing)")
            return _interp(t, ts, spd * np.cos(crs)), _interp(t, ts, spd * np.sin(crs)), "GPS.Spd/GCrs"
        reason = "GPS.Spd/GCrs (no fix)"
    why.append(reason)
    notes.append(f"velocity differentiated from the position ({'; '.join(why)} missing)")
    return _derivative(t, north), _derivative(t, east), "position differentiated"


def _heading(columns, series, t):
    why = []
    for name in ("XKF1", "ATT", "AHR2"):
        reason = _need(columns, series, name, ("Yaw",))
        if reason is None:
            s = series[name]
            rows = _primary_core(s)[0] if name == "XKF1" else np.ones(len(s.rows), bool)
            psi = _unwrap_deg(s.array("Yaw")[rows])
            return _interp(t, s.time_s[rows], psi), f"{name}.Yaw"
        why.append(reason)
    raise InputError("no heading: tried " + ", ".join(why))


def _yaw_rate(columns, series, t, psi, notes):
    reason = _need(columns, series, "IMU", ("GyrZ",))
    if reason is None:
        s = series["IMU"]
        rows = (s.array("I") == np.nanmin(s.array("I"))) if "I" in s.columns else slice(None)
        r = _interp(t, s.time_s[rows], s.array("GyrZ")[rows])
        source = "IMU.GyrZ"
        if _need(columns, series, "XKF1", ("GZ",)) is None:
            x = series["XKF1"]
            core = _primary_core(x)[0]
            r = r - np.radians(_interp(t, x.time_s[core], x.array("GZ")[core]))
            source = "IMU.GyrZ - XKF1.GZ"
        return r, source
    notes.append(f"yaw rate differentiated from the heading ({reason} missing)")
    return _derivative(t, psi), "heading differentiated"


def _commands(path, commands, errors, series, columns, notes):
    """(t, nT, nS, source, manual_only) of the servo commands."""
    if commands["RCOU"]:
        arr = np.array(commands["RCOU"])
        return arr[:, 0], arr[:, 1], arr[:, 2], "RCOU with SERVOn_* (PARM)", False
    why = ["RCOU (" + (errors.get("RCOU") or ("no records" if "RCOU" in columns
                                               else "not in the log")) + ")"]
    if commands["RCIN"]:
        arr = np.array(commands["RCIN"])
        notes.append(f"commands from RCIN in MANUAL while armed ({why[0]})")
        return arr[:, 0], arr[:, 1], arr[:, 2], "RCIN with RCMAP_*/RCn_* (PARM), MANUAL", True
    why.append("RCIN (" + (errors.get("RCIN") or ("no records" if "RCIN" in columns
                                                   else "not in the log")) + ")")
    raise InputError(f"{path}: no commands: tried " + ", ".join(why)
                     + "; the servo outputs (RCOU, fields C1..C14) and the PARM records of "
                       "SERVOn_FUNCTION (26 steering, 70 throttle) and SERVOn_MIN/MAX/TRIM/REVERSED "
                       "are needed")


def _rate_limited(t: np.ndarray, values: np.ndarray, rate: float) -> np.ndarray:
    """An actuator following `values` at most `rate` per second (0: no limit)."""
    if not rate:
        return values
    out = values.copy()
    for k in range(1, len(out)):
        step = rate * max(0.0, t[k] - t[k - 1])
        out[k] = out[k - 1] + np.clip(values[k] - out[k - 1], -step, step)
    return out


def _interval_means(grid, t, y):
    """Mean of the piecewise-constant signal (t, y) over each [grid[k], grid[k+1])."""
    # integral of the zero-order hold, evaluated at the grid points
    dt = np.diff(t)
    cum = np.concatenate([[0.0], np.cumsum(y[:-1] * dt)])

    def integral(x):
        k = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 1)
        return cum[k] + y[k] * (x - t[k])

    g = integral(grid)
    means = np.diff(g) / np.diff(grid)
    return np.append(means, y[np.clip(np.searchsorted(t, grid[-1], "right") - 1, 0, len(t) - 1)])


def _step_function(grid, t, y, default):
    k = np.searchsorted(t, grid, side="right") - 1
    out = np.full(len(grid), default, dtype=float)
    ok = k >= 0
    out[ok] = y[k[ok]]
    return out


def read_dataflash(path: str | Path, sample_s: float = 0.1,
                   actuator_rates: tuple[float, float] = (0.0, 0.0)) -> FlightLog:
    """Read a DataFlash log into a FlightLog (see the module docstring). `actuator_rates`
    (%/s, throttle and steering) make the commands follow the servo outputs no faster than the
    actuators do, for logs whose commands jump."""
    path = Path(path)
    if not (math.isfinite(sample_s) and sample_s > 0):
        raise InputError(f"sample interval must be positive, got {sample_s!r}")
    columns, series, params, commands, errors = _read_messages(path)
    notes: list[str] = [errors.pop("truncated")] if "truncated" in errors else []
    try:
        t_pos, north, east, pos_src = _position(columns, series, notes)
        order = np.argsort(t_pos, kind="stable")
        t_pos, north, east = t_pos[order], north[order], east[order]
        keep = np.concatenate([[True], np.diff(t_pos) > 0])
        t_pos, north, east = t_pos[keep], north[keep], east[keep]
        if len(t_pos) < 2:
            raise InputError(f"only {len(t_pos)} position record(s) ({pos_src})")
        n = int(math.floor((t_pos[-1] - t_pos[0]) / sample_s + 1e-6)) + 1
        grid = t_pos[0] + sample_s * np.arange(n)
        x, y = _interp(grid, t_pos, north), _interp(grid, t_pos, east)
        vn, ve, vel_src = _velocity(columns, series, grid, x, y, notes)
        psi, psi_src = _heading(columns, series, grid)
        r, r_src = _yaw_rate(columns, series, grid, psi, notes)
        t_cmd, nT, nS, cmd_src, manual_only = _commands(path, commands, errors, series, columns,
                                                        notes)
    except InputError as exc:
        text = str(exc)
        raise InputError(text if text.startswith(str(path)) else f"{path}: {text}") from None
    # gaps in the position: not measured across them
    gap = np.zeros(len(grid), bool)
    for a, b in zip(t_pos[:-1][np.diff(t_pos) > MAX_GAP_S], t_pos[1:][np.diff(t_pos) > MAX_GAP_S]):
        gap |= (grid > a) & (grid < b)
        notes.append(f"no position from t = {a:.1f} to {b:.1f} s: not measured there")
    c, s = np.cos(psi), np.sin(psi)
    u, v = c * vn + s * ve, -s * vn + c * ve
    states = np.column_stack([x, y, np.arctan2(s, c), u, v, r])
    states[gap] = np.nan
    nT = _rate_limited(t_cmd, nT, actuator_rates[0])
    nS = _rate_limited(t_cmd, nS, actuator_rates[1])
    if any(actuator_rates):
        notes.append(f"commands rate-limited to {actuator_rates[0]:g} and {actuator_rates[1]:g} %/s")
    cmds = np.column_stack([_interval_means(grid, t_cmd, nT), _interval_means(grid, t_cmd, nS)])
    cmds[(grid < t_cmd[0]) | (grid > t_cmd[-1] + MAX_GAP_S)] = np.nan
    mode = np.full(len(grid), -1.0)
    if series.get("MODE") and series["MODE"].rows:
        m = series["MODE"]
        mode = _step_function(grid, m.time_s, m.array("Mode"), -1.0)
    armed = np.zeros(len(grid), bool)
    if series.get("ARM") and series["ARM"].rows:
        a = series["ARM"]
        armed = _step_function(grid, a.time_s, a.array("ArmState"), 0.0) > 0
    elif np.any(np.isfinite(cmds)):
        armed[:] = True  # no ARM records: take the servo outputs as they are
    if manual_only:
        cmds[~((mode == MANUAL) & armed)] = np.nan
    sources = {"position": pos_src, "velocity": vel_src, "heading": psi_src, "yaw rate": r_src,
               "commands": cmd_src}
    return FlightLog(str(path), grid, states, cmds, mode, armed, sources, params, tuple(notes))
