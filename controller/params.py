"""Boat model parameters: the paper's identified values, their units, and TOML files.

One table of names serves TOML, FMI variables, the CLI and the code (DESIGN.md,
Conventions). Values are SI inside; the one exception at the human edge is `delta_max`,
which TOML files give in degrees and which is converted here, once.

Units decision (DESIGN.md): the paper's `c` fits commands in hundredths of a percent, so
the thrust is `F = c * thrust_scale**2 * nT * |nT|` with `nT` in percent and
`thrust_scale = 100`.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import numpy as np

from .errors import InputError


@dataclass(frozen=True)
class ParamInfo:
    """What one model parameter is: unit (SI, as FMI declares it) and a one-line meaning."""

    unit: str
    description: str


# Order matters: it is the order of the symbolic parameter vector of the model, of the FMU's
# value references, and of the identification NLP.
PARAM_INFO: dict[str, ParamInfo] = {
    "m11": ParamInfo("kg", "surge mass including added mass"),
    "m22": ParamInfo("kg", "sway mass including added mass"),
    "m33": ParamInfo("kg.m2", "yaw moment of inertia including added inertia"),
    "Xu": ParamInfo("kg/s", "linear surge damping X_u"),
    "Yv": ParamInfo("kg/s", "linear sway damping Y_v"),
    "Yr": ParamInfo("kg.m/s", "linear sway damping due to yaw rate Y_r"),
    "Nv": ParamInfo("kg.m/s", "linear yaw damping due to sway N_v"),
    "Nr": ParamInfo("kg.m2/s", "linear yaw damping N_r"),
    "Xuu": ParamInfo("kg/m", "quadratic surge damping X_u|u|"),
    "Yvv": ParamInfo("kg/m", "quadratic sway damping Y_v|v|"),
    "Yrr": ParamInfo("kg.m", "quadratic sway damping due to yaw rate Y_r|r|"),
    "Nvv": ParamInfo("kg", "quadratic yaw damping due to sway N_v|v|"),
    "Nrr": ParamInfo("kg.m2", "quadratic yaw damping N_r|r|"),
    "c": ParamInfo("N", "thrust coefficient per (thrust_scale * nT)^2, as published"),
    "thrust_scale": ParamInfo("1", "command units per percent that c was identified in (100)"),
    "ly": ParamInfo("m", "lever arm from the origin to the outboard motor"),
    "delta_max": ParamInfo("rad", "motor angle at full steering command"),
}
PARAM_NAMES: tuple[str, ...] = tuple(PARAM_INFO)

# Parameters that must be strictly positive for the model to make sense.
POSITIVE_PARAMS = ("m11", "m22", "m33", "thrust_scale", "ly", "delta_max")
# Parameters given in degrees in TOML files (and radians everywhere else).
DEGREE_PARAMS = ("delta_max",)


@dataclass(frozen=True)
class BoatParams:
    """One parameter set of the 3-DOF model; the defaults are the paper's identified values."""

    m11: float = 1.9149e3
    m22: float = 1.8238e3
    m33: float = 1.9351e3
    Xu: float = -29.220
    Yv: float = -3.6284e3
    Yr: float = -1.6080e-4
    Nv: float = -1.3102e-4
    Nr: float = -2.1940e3
    Xuu: float = -54.344
    Yvv: float = -282.62
    Yrr: float = -0.0025
    Nvv: float = -0.0010
    Nrr: float = -206.44
    c: float = 1.3331e-5
    thrust_scale: float = 100.0
    ly: float = 3.0
    delta_max: float = math.radians(25.0)

    def __post_init__(self) -> None:
        for name in PARAM_NAMES:
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                raise InputError(f"boat parameter {name!r}: expected a number, got {value!r}")
            if not math.isfinite(value):
                raise InputError(f"boat parameter {name!r}: value {value!r} is not finite")
        for name in POSITIVE_PARAMS:
            if getattr(self, name) <= 0.0:
                raise InputError(
                    f"boat parameter {name!r}: must be positive, got {getattr(self, name)!r}"
                )

    @property
    def c_eff(self) -> float:
        """Thrust coefficient in N per percent squared: `c * thrust_scale**2`."""
        return self.c * self.thrust_scale**2

    def as_vector(self) -> np.ndarray:
        """Values in PARAM_NAMES order: the numeric value of the model's parameter input."""
        return np.array([getattr(self, n) for n in PARAM_NAMES], dtype=float)

    @classmethod
    def from_vector(cls, values) -> "BoatParams":
        values = np.asarray(values, dtype=float).ravel()
        if values.size != len(PARAM_NAMES):
            raise InputError(f"expected {len(PARAM_NAMES)} parameter values, got {values.size}")
        return cls(**{n: float(v) for n, v in zip(PARAM_NAMES, values)})

    def as_dict(self) -> dict[str, float]:
        return asdict(self)

    def replace(self, **changes: float) -> "BoatParams":
        unknown = set(changes) - set(PARAM_NAMES)
        if unknown:
            raise InputError(f"unknown boat parameter(s): {', '.join(sorted(unknown))}")
        return replace(self, **changes)

    def scaled(self, factor: float) -> "BoatParams":
        """Every force-like parameter times `factor`: the model's equations do not change."""
        kept = {"thrust_scale", "ly", "delta_max"}
        return replace(
            self, **{n: getattr(self, n) * factor for n in PARAM_NAMES if n not in kept}
        )

    # -- TOML ---------------------------------------------------------------------------
    @classmethod
    def from_mapping(cls, table: dict, source: str = "<mapping>") -> "BoatParams":
        """Build from a TOML-like table (delta_max in degrees); unset names keep defaults."""
        known = {f.name for f in fields(cls)}
        values: dict[str, float] = {}
        for key, value in table.items():
            if key not in known:
                raise InputError(
                    f"{source}: unknown boat parameter {key!r} (known: {', '.join(PARAM_NAMES)})"
                )
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"{source}: field {key!r}: expected a number, got {value!r}")
            values[key] = math.radians(value) if key in DEGREE_PARAMS else float(value)
        try:
            return cls(**values)
        except InputError as exc:
            raise InputError(f"{source}: {exc}") from None

    @classmethod
    def from_toml(cls, path: str | Path) -> "BoatParams":
        """Load the `[boat]` table of a TOML file (or the top level if it has none)."""
        path = Path(path)
        try:
            text = path.read_bytes().decode("utf-8")
        except FileNotFoundError:
            raise InputError(f"{path}: no such parameter file") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: cannot read the parameter file: {exc}") from None
        return cls.from_toml_text(text, str(path))

    @classmethod
    def from_toml_text(cls, text: str, source: str = "<string>") -> "BoatParams":
        """`from_toml` of a file's text; `source` names it in errors."""
        path = source
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"{path}: not valid TOML: {exc}") from None
        table = doc.get("boat", doc)
        if not isinstance(table, dict):
            raise InputError(f"{path}: field 'boat' must be a table")
        return cls.from_mapping(table, source=f"{path}: [boat]" if "boat" in doc else str(path))

    def to_toml(self, header: str = "") -> str:
        """TOML text with a `[boat]` table; each line carries its unit as a comment."""
        lines = []
        if header:
            lines += [f"# {h}" if h else "#" for h in header.splitlines()]
        lines.append("[boat]")
        for name in PARAM_NAMES:
            value = getattr(self, name)
            unit = PARAM_INFO[name].unit
            if name in DEGREE_PARAMS:
                value, unit = round(math.degrees(value), 9), "deg"  # 30.0, not 29.999999999999996
            lines.append(f"{name} = {value!r}  # {unit}: {PARAM_INFO[name].description}")
        return "\n".join(lines) + "\n"

    def save_toml(self, path: str | Path, header: str = "") -> None:
        Path(path).write_text(self.to_toml(header))


IDENTIFIED = BoatParams()
"""The paper's Table "System identification results" with the units decision applied."""
