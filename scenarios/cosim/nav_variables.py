"""The navigation FMU's variables, written once: both FMI wrappers register them from here.

Inputs carry the boat FMU's output names (`fmu.variables`), so a system connects them name
to name; outputs carry its input names for the commands.
"""

from __future__ import annotations

from dataclasses import dataclass

from fmu.variables import STATE_UNITS, STATE_WORDS, VARIABLES as BOAT_VARIABLES
from scenarios.cosim.navigation import STATUS_CODES

IMU_PERIOD_S = 0.01
"""The step the navigation FMU is stepped at (or a whole fraction of it): the IMU period."""


@dataclass(frozen=True)
class NavVariable:
    """One variable of the navigation FMU; kind: real | integer | string."""

    name: str
    kind: str
    causality: str  # input | output | parameter
    unit: str  # an `fmu.variables.UNITS` name ("" for integers and strings)
    description: str
    start: object = None


def _boat(name: str):
    return next(v for v in BOAT_VARIABLES if v.name == name)


STATE_INPUTS = ("x", "y", "psi", "u", "v", "r")
ACCEL_INPUTS = ("u_dot", "v_dot", "r_dot")
ACTUATOR_INPUTS = ("nT_actual", "nS_actual")
COMMAND_OUTPUTS = ("nT", "nS")

_codes = ", ".join(f"{v} {k}" for k, v in STATUS_CODES.items())

VARIABLES: tuple[NavVariable, ...] = (
    tuple(NavVariable(n, "real", "input", u, f"boat's {w} (boat FMU output {n})", 0.0)
          for n, u, w in zip(STATE_INPUTS, STATE_UNITS, STATE_WORDS))
    + tuple(NavVariable(n, "real", "input", _boat(n).unit,
                        f"{_boat(n).description} (boat FMU output {n}; feeds the simulated AHRS)",
                        0.0) for n in ACCEL_INPUTS)
    + tuple(NavVariable(n, "real", "input", "%",
                        f"{_boat(n).description} (boat FMU output {n}; what the controller "
                        f"takes as the actuators' position)", 0.0) for n in ACTUATOR_INPUTS)
    + (
        NavVariable("nT", "real", "output", "%", "throttle command, held for 0.1 s "
                    "(to the boat FMU's input nT)"),
        NavVariable("nS", "real", "output", "%", "steering command, positive turns to port, "
                    "held for 0.1 s (to the boat FMU's input nS)"),
        NavVariable("status", "integer", "output", "",
                    f"what the controller did this control period: {_codes}"),
        NavVariable("slack", "real", "output", "m",
                    "the NMPC's largest slack on the separation this period (0: kept)"),
        NavVariable("clearance", "real", "output", "m",
                    "least distance from the hull circles at the estimated pose to the wall "
                    "segments the controller saw (1e9: none seen)"),
        NavVariable("cross_track", "real", "output", "m",
                    "distance of the estimated position from the waypoint path"),
        NavVariable("controller", "string", "parameter", "",
                    "nmpc | los-pid | lexicographic (empty: the scenario's)", ""),
        NavVariable("perception", "string", "parameter", "",
                    "known-walls (the true walls within range, the paper's simulation "
                    "assumption) | lidar (the simulated LiDAR rendered from the embedded canal "
                    "and detected) (empty: the scenario's)", ""),
        NavVariable("seed", "integer", "parameter", "",
                    "seed of the simulated sensors (-1: the scenario's)", -1),
        NavVariable("log_path", "string", "parameter", "",
                    "the controller's own log.csv, one row per control period (empty: none)",
                    ""),
    )
)

UNIT_NAMES = tuple(sorted({v.unit for v in VARIABLES if v.unit} | {"s"}))  # "s": FMI 3.0 time
