"""The FMU's variable table, written once: both modelDescription files and the C enum come from it.

Value references are positions in `VARIABLES`. Groups the generated C passes to the model as
one vector (state, actuators, commands, current, parameters, rate limits) are contiguous, in
the order of `controller.model`'s inputs, so the C wrapper hands out pointers, never copies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from controller.model import CURRENT_NAMES, INPUT_NAMES, STATE_NAMES
from controller.params import IDENTIFIED, PARAM_INFO, PARAM_NAMES, POSITIVE_PARAMS, BoatParams

DEFAULT_INTERNAL_STEP_S = 0.05


@dataclass(frozen=True)
class Unit:
    """An FMI unit: its SI base-unit exponents and, optionally, one display unit."""

    name: str
    base: tuple[tuple[str, int], ...] = ()
    factor: float = 1.0
    display: tuple[str, float] | None = None  # (name, factor): display = factor * value


UNITS: dict[str, Unit] = {u.name: u for u in (
    Unit("s", (("s", 1),)),
    Unit("m", (("m", 1),)),
    Unit("m/s", (("m", 1), ("s", -1))),
    Unit("m/s2", (("m", 1), ("s", -2))),
    Unit("rad", (("rad", 1),), display=("deg", 180.0 / math.pi)),
    Unit("rad/s", (("rad", 1), ("s", -1)), display=("deg/s", 180.0 / math.pi)),
    Unit("rad/s2", (("rad", 1), ("s", -2)), display=("deg/s2", 180.0 / math.pi)),
    Unit("%", (), factor=0.01),
    Unit("%/s", (("s", -1),), factor=0.01),
    Unit("1", ()),
    Unit("N", (("kg", 1), ("m", 1), ("s", -2))),
    Unit("kg", (("kg", 1),)),
    Unit("kg.m2", (("kg", 1), ("m", 2))),
    Unit("kg/s", (("kg", 1), ("s", -1))),
    Unit("kg.m/s", (("kg", 1), ("m", 1), ("s", -1))),
    Unit("kg.m2/s", (("kg", 1), ("m", 2), ("s", -1))),
    Unit("kg/m", (("kg", 1), ("m", -1))),
    Unit("kg.m", (("kg", 1), ("m", 1))),
)}


@dataclass(frozen=True)
class Variable:
    """One FMI variable (a Float64 / Real); `start` is None where FMI forbids one."""

    name: str
    causality: str  # independent | input | output | parameter
    variability: str  # continuous | fixed | tunable
    unit: str
    description: str
    start: float | None = None
    initial: str | None = None  # exact | calculated | None (independent, input: implied)
    min: float | None = None
    max: float | None = None
    positive: bool = False  # the C side rejects values <= 0
    group: str = ""  # which model input vector the variable belongs to (C pointer groups)

    @property
    def display_unit(self) -> str | None:
        u = UNITS[self.unit]
        return u.display[0] if u.display else None


STATE_UNITS = ("m", "m", "rad", "m/s", "m/s", "rad/s")
STATE_WORDS = ("north position", "east position", "heading from north, clockwise",
               "surge velocity over ground", "sway velocity over ground", "yaw rate")


def _table(params: BoatParams) -> tuple[Variable, ...]:
    v: list[Variable] = [Variable(
        "time", "independent", "continuous", "s", "simulation time")]
    v += [
        Variable("nT", "input", "continuous", "%", "throttle command", 0.0, None, -100, 100,
                 group="cmd"),
        Variable("nS", "input", "continuous", "%",
                 "steering command (positive turns to port)", 0.0, None, -100, 100, group="cmd"),
    ]
    v += [Variable(n, "input", "continuous", "m/s", f"water current toward {n.split('_')[1]}",
                   0.0, group="current") for n in CURRENT_NAMES]
    v += [Variable(n, "output", "continuous", u, d, initial="calculated", group="x")
          for n, u, d in zip(STATE_NAMES, STATE_UNITS, STATE_WORDS)]
    v += [Variable(f"{n}_dot", "output", "continuous", u, f"body-frame {w} acceleration",
                   initial="calculated", group="accel")
          for n, u, w in zip(("u", "v", "r"), ("m/s2", "m/s2", "rad/s2"),
                             ("surge", "sway", "yaw"))]
    v += [Variable(f"{n}_actual", "output", "continuous", "%",
                   f"{w} after the actuator rate limit", initial="calculated", group="act")
          for n, w in zip(INPUT_NAMES, ("throttle", "steering"))]
    for name in PARAM_NAMES:
        info = PARAM_INFO[name]
        v.append(Variable(name, "parameter", "tunable", info.unit, info.description,
                          float(getattr(params, name)), "exact", positive=name in POSITIVE_PARAMS,
                          group="p"))
    v += [
        Variable("dnT_max", "parameter", "tunable", "%/s",
                 "throttle rate limit (0 = off; the real throttle: 10)", 0.0, "exact", min=0.0,
                 group="rate"),
        Variable("dnS_max", "parameter", "tunable", "%/s",
                 "steering rate limit (0 = off; the real steering: 40)", 0.0, "exact", min=0.0,
                 group="rate"),
    ]
    v += [Variable(f"{n}0", "parameter", "fixed", u, f"initial {d}", 0.0, "exact", group="x0")
          for n, u, d in zip(STATE_NAMES, STATE_UNITS, STATE_WORDS)]
    v += [Variable(f"{n}0", "parameter", "fixed", "%", f"initial {w} actuator position",
                   0.0, "exact", -100, 100, group="act0")
          for n, w in zip(INPUT_NAMES, ("throttle", "steering"))]
    v.append(Variable(
        "internal_step", "parameter", "tunable", "s",
        "largest internal RK4 step; each communication step is cut into equal steps no longer "
        "than this", DEFAULT_INTERNAL_STEP_S, "exact", positive=True))
    return tuple(v)


def variables(params: BoatParams = IDENTIFIED) -> tuple[Variable, ...]:
    """The variable table with `params` as the model parameters' start values."""
    table = _table(params)
    _check_groups(table)
    return table


GROUP_ORDER = {  # the order controller.model expects inside each vector
    "x": STATE_NAMES,
    "x0": tuple(f"{n}0" for n in STATE_NAMES),
    "act": tuple(f"{n}_actual" for n in INPUT_NAMES),
    "act0": tuple(f"{n}0" for n in INPUT_NAMES),
    "cmd": INPUT_NAMES,
    "current": CURRENT_NAMES,
    "p": PARAM_NAMES,
    "rate": ("dnT_max", "dnS_max"),
    "accel": ("u_dot", "v_dot", "r_dot"),
}


def _check_groups(table) -> None:
    """Each group must sit contiguously in the model's order: the C code relies on it."""
    names = [v.name for v in table]
    for group, order in GROUP_ORDER.items():
        first = names.index(order[0])
        if tuple(names[first:first + len(order)]) != tuple(order):
            raise AssertionError(f"variable group {group!r} is not contiguous in model order")
        if any(table[first + i].group != group for i in range(len(order))):
            raise AssertionError(f"variable group {group!r} is mislabelled")


VARIABLES = variables()
VR: dict[str, int] = {var.name: i for i, var in enumerate(VARIABLES)}
"""Value reference by name (the same for every parameter set and both FMI versions)."""

OUTPUT_NAMES = tuple(v.name for v in VARIABLES if v.causality == "output")
PARAMETER_NAMES = tuple(v.name for v in VARIABLES if v.causality == "parameter")


def dependencies_at_initialization(var: Variable) -> tuple[str, ...]:
    """What an output's initial value depends on (ModelStructure/InitialUnknowns)."""
    if var.group == "x":
        return (f"{var.name}0",)
    if var.group == "act":
        return (var.name.replace("_actual", "0"),)
    if var.group == "accel":
        # f(x0, act0, p, current): position does not enter the accelerations
        return (("psi0", "u0", "v0", "r0", "nT0", "nS0") + PARAM_NAMES + CURRENT_NAMES)
    raise ValueError(f"{var.name} is not an output")
