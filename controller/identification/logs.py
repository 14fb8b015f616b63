"""Manoeuvre logs: the CSV format that `canalnav maneuvers` writes and `canalnav sysid` reads.

A log is comment lines (`# key: value` pairs are metadata), one header row naming the columns
with their units, e.g. `psi [deg]`, then one row per sample. Required columns: time, u, psi,
nT, nS; optional: x, y, v, r. Real logs may lack the optional columns or sample some at
another rate: an empty cell means "not measured at this sample" and gets zero weight in the
identification; commands are held from the last row that gives them. What is wrong in a file
(a missing column, time not increasing, NaN or text in a number) is an `InputError` naming the
file, the line and the column.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, where
from ..params import PARAM_NAMES, BoatParams

FORMAT_LINE = "canalnav maneuver log, format 1"

STATE_COLUMNS = ("x", "y", "psi", "u", "v", "r")  # the model's state order
COMMAND_COLUMNS = ("nT", "nS")
REQUIRED_COLUMNS = ("time", "psi", "u", "nT", "nS")

# Accepted units per column and the factor to SI (radians, metres, seconds, percent for commands).
UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0},
    "x": {"m": 1.0},
    "y": {"m": 1.0},
    "psi": {"deg": math.pi / 180.0, "rad": 1.0},
    "u": {"m/s": 1.0},
    "v": {"m/s": 1.0},
    "r": {"deg/s": math.pi / 180.0, "rad/s": 1.0},
    "nT": {"%": 1.0},
    "nS": {"%": 1.0},
}
# The units `write_log` uses (degrees at this human-facing edge, SI otherwise).
WRITE_UNITS = {"time": "s", "x": "m", "y": "m", "psi": "deg", "u": "m/s", "v": "m/s",
               "r": "deg/s", "nT": "%", "nS": "%"}
_WRITE_FORMAT = {"time": "{:.3f}", "x": "{:.4f}", "y": "{:.4f}", "psi": "{:.4f}",
                 "u": "{:.5f}", "v": "{:.5f}", "r": "{:.5f}", "nT": "{:.3f}", "nS": "{:.3f}"}

# Values of the `maneuver` header and what identification does with them.
SURGE_MANEUVERS = ("acceleration", "deceleration", "surge")
SWAY_YAW_MANEUVERS = ("zigzag", "turn", "sway-yaw")
USES = ("fit", "heldout")
STRAIGHT_STEERING_PCT = 1.0
"""A log without a `maneuver` header whose |nS| never exceeds this is a surge run."""

_HEADER_CELL = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(?:[\[(]\s*([^\])]*?)\s*[\])])?\s*$")
_META_LINE = re.compile(r"^#\s*([A-Za-z_][\w.\-]*)\s*:\s*(.*?)\s*$")


@dataclass(frozen=True, eq=False)
class ManeuverLog:
    """One manoeuvre: samples in SI units (psi, r in radians), NaN where a state was not measured.

    `states` is (N, 6) in the model's order x, y, psi, u, v, r; `commands` is (N, 2) nT, nS in
    percent, the value applied from this sample to the next; `meta` holds the header's
    `key: value` pairs; `lines` the file line of each sample (for error messages).
    """

    time_s: np.ndarray
    states: np.ndarray
    commands: np.ndarray
    meta: Mapping[str, str] = field(default_factory=dict)
    source: str = "<memory>"
    lines: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.time_s)
        if self.states.shape != (n, len(STATE_COLUMNS)) or self.commands.shape != (n, 2):
            raise ValueError("time_s, states (N, 6) and commands (N, 2) must have N rows")

    @property
    def n_samples(self) -> int:
        return len(self.time_s)

    @property
    def maneuver(self) -> str:
        """`surge` or `sway-yaw`: from the `maneuver` header, else from the steering content."""
        tag = self.meta.get("maneuver", "").strip().lower()
        if tag in SURGE_MANEUVERS:
            return "surge"
        if tag in SWAY_YAW_MANEUVERS:
            return "sway-yaw"
        return "surge" if np.nanmax(np.abs(self.commands[:, 1])) <= STRAIGHT_STEERING_PCT else "sway-yaw"

    @property
    def heldout(self) -> bool:
        """True when the header says `use: heldout`: the run checks a fit and never enters it."""
        return self.meta.get("use", "fit").strip().lower() == "heldout"

    def line_of(self, i: int) -> int | None:
        return None if self.lines is None else int(self.lines[i])

    def measured(self, name: str) -> np.ndarray:
        """Boolean mask of the samples where state `name` was measured."""
        return np.isfinite(self.states[:, STATE_COLUMNS.index(name)])

    def truth(self) -> BoatParams | None:
        """The true parameters from `true.<name>` header lines (generated logs), else None."""
        values = {}
        for name in PARAM_NAMES:
            text = self.meta.get(f"true.{name}")
            if text is None:
                return None
            try:
                values[name] = float(text.split()[0])
            except (ValueError, IndexError):
                raise InputError(
                    f"{self.source}: header 'true.{name}': expected a number, got {text!r}"
                ) from None
        return BoatParams(**values)


def with_truth_meta(meta: Mapping[str, str], params: BoatParams) -> dict[str, str]:
    """`meta` plus `true.<name>` lines (SI units) so identification can report the truth."""
    out = dict(meta)
    for name in PARAM_NAMES:
        out[f"true.{name}"] = repr(float(getattr(params, name)))
    return out


# -- writing ----------------------------------------------------------------------------------
def format_log(log: ManeuverLog) -> str:
    """The CSV text of a log: metadata comments, the header row with units, one row a sample."""
    out = io.StringIO()
    out.write(f"# {FORMAT_LINE}\n")
    for key, value in log.meta.items():
        out.write(f"# {key}: {value}\n")
    columns = ("time",) + STATE_COLUMNS + COMMAND_COLUMNS
    out.write(",".join(f"{c} [{WRITE_UNITS[c]}]" for c in columns) + "\n")
    si = np.column_stack([log.time_s, log.states, log.commands])
    for row in si:
        cells = []
        for c, value in zip(columns, row):
            if not math.isfinite(value):
                cells.append("")
            else:
                cells.append(_WRITE_FORMAT[c].format(value / UNITS[c][WRITE_UNITS[c]]))
        out.write(",".join(cells) + "\n")
    return out.getvalue()


def write_log(path: str | Path, log: ManeuverLog) -> None:
    Path(path).write_text(format_log(log))


# -- reading ----------------------------------------------------------------------------------
def read_log(path: str | Path) -> ManeuverLog:
    """Read and validate one CSV log; errors name the file, line and column."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise InputError(f"{path}: no such log file") from None
    except (UnicodeDecodeError, IsADirectoryError) as exc:
        raise InputError(f"{path}: not a readable text file ({exc.__class__.__name__})") from None
    return parse_log(text, source=str(path))


def _parse_header(cells: list[str], source: str, line: int) -> list[tuple[str, float] | None]:
    """Per CSV column: (canonical name, factor to SI), or None for a column we do not use."""
    known = {name.lower(): name for name in UNITS}
    known.update({"t": "time", "heading": "psi", "nt": "nT", "ns": "nS"})
    out: list[tuple[str, float] | None] = []
    seen: dict[str, int] = {}
    for k, cell in enumerate(cells):
        m = _HEADER_CELL.match(cell)
        name = known.get(m.group(1).lower()) if m else None
        if name is None:
            out.append(None)  # extra columns (lat, lon, battery...) are allowed and ignored
            continue
        if name in seen:
            raise InputError(f"{where(source, line, cell.strip())}duplicate column "
                             f"(also column {seen[name] + 1})")
        seen[name] = k
        unit = (m.group(2) or "").strip()
        units = UNITS[name]
        if not unit:
            if len(units) > 1:
                raise InputError(
                    f"{where(source, line, cell.strip())}give the unit, e.g. "
                    + " or ".join(f"'{name} [{u}]'" for u in units)
                )
            unit = next(iter(units))
        if unit not in units:
            raise InputError(
                f"{where(source, line, cell.strip())}unknown unit {unit!r} "
                f"(accepted: {', '.join(units)})"
            )
        out.append((name, units[unit]))
    missing = [c for c in REQUIRED_COLUMNS if c not in seen]
    if missing:
        raise InputError(
            f"{where(source, line)}missing required column(s) "
            + ", ".join(f"'{c}'" for c in missing)
            + f" (header: {', '.join(c.strip() for c in cells)}; required: "
            + ", ".join(f"{c} [{WRITE_UNITS[c]}]" for c in REQUIRED_COLUMNS) + ")"
        )
    return out


def _number(cell: str, source: str, line: int, column: str) -> float:
    try:
        value = float(cell)
    except ValueError:
        raise InputError(f"{where(source, line, column)}expected a number, got {cell!r}") from None
    if not math.isfinite(value):
        raise InputError(
            f"{where(source, line, column)}value {cell!r} is not finite "
            "(leave the cell empty if it was not measured)"
        )
    return value


def parse_log(text: str, source: str = "<log>") -> ManeuverLog:
    """Parse the CSV text of a log (see the module docstring); `source` names it in errors."""
    meta: dict[str, str] = {}
    header: list[tuple[str, float] | None] | None = None
    header_cells: list[str] = []
    header_line = 0
    rows: list[tuple[int, list[str]]] = []
    for line_no, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            m = _META_LINE.match(stripped)
            if m and header is None:
                meta[m.group(1)] = m.group(2)
            continue
        cells = next(csv.reader([raw]))
        if header is None:
            header, header_cells, header_line = _parse_header(cells, source, line_no), cells, line_no
        else:
            rows.append((line_no, cells))
    if header is None:
        raise InputError(f"{source}: no header row (expected e.g. "
                         + ",".join(f"{c} [{WRITE_UNITS[c]}]" for c in REQUIRED_COLUMNS) + ")")
    if len(rows) < 2:
        raise InputError(f"{where(source, header_line)}only {len(rows)} data row(s) after the "
                         "header: a log needs samples over time")
    if meta.get("use", "fit").strip().lower() not in USES:
        raise InputError(f"{source}: header 'use': expected one of {', '.join(USES)}, "
                         f"got {meta['use']!r}")

    n = len(rows)
    time_s = np.empty(n)
    states = np.full((n, len(STATE_COLUMNS)), np.nan)
    commands = np.full((n, 2), np.nan)
    lines = np.array([ln for ln, _ in rows], dtype=int)
    for i, (line_no, cells) in enumerate(rows):
        if len(cells) != len(header_cells):
            raise InputError(f"{where(source, line_no)}{len(cells)} fields, the header has "
                             f"{len(header_cells)}")
        for k, spec in enumerate(header):
            if spec is None:
                continue
            name, factor = spec
            cell = cells[k].strip()
            column = header_cells[k].strip()
            if not cell:
                if name == "time":
                    raise InputError(f"{where(source, line_no, column)}empty: every row needs "
                                     "a time")
                continue
            value = _number(cell, source, line_no, column) * factor
            if name == "time":
                time_s[i] = value
            elif name in COMMAND_COLUMNS:
                commands[i, COMMAND_COLUMNS.index(name)] = value
            else:
                states[i, STATE_COLUMNS.index(name)] = value
        if i > 0 and time_s[i] <= time_s[i - 1]:
            column = header_cells[[s[0] if s else None for s in header].index("time")].strip()
            raise InputError(
                f"{where(source, line_no, column)}time not increasing "
                f"({time_s[i]:g} s after {time_s[i - 1]:g} s on line {lines[i - 1]})"
            )
    for j, name in enumerate(COMMAND_COLUMNS):
        given = np.isfinite(commands[:, j])
        if not given.any():
            raise InputError(f"{source}: column {name!r}: no values at all")
        # Commands are held: fill forward, and before the first value use that first value.
        idx = np.where(given, np.arange(n), 0)
        np.maximum.accumulate(idx, out=idx)
        first = int(np.argmax(given))
        filled = commands[idx, j]
        filled[:first] = commands[first, j]
        commands[:, j] = filled
    for name in ("u", "psi"):
        j = STATE_COLUMNS.index(name)
        if not np.isfinite(states[:, j]).any():
            raise InputError(f"{source}: column {name!r}: no values at all")
    return ManeuverLog(time_s, states, commands, meta, source, lines)
