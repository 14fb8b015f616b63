"""What both navigation FMU wrappers write into their model descriptions beyond variables:
unit definitions (from `fmu.variables.UNITS`, as the boat FMU has them) and the default
experiment from the embedded scenario."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement

from fmu.variables import UNITS
from scenarios.cosim.nav_variables import IMU_PERIOD_S, UNIT_NAMES

SYSTEM_STEP_S = 0.01
"""The co-simulation's communication step: the IMU period, the boat's step in `canalnav run`
(the navigation FMU works one step ahead, so the master's one-step delay cancels)."""


@dataclass(frozen=True)
class ModelMeta:
    description: str
    duration_s: float
    step_s: float = SYSTEM_STEP_S


def describe_model(scenario_json: Path) -> ModelMeta:
    """The FMU's description and default experiment from its embedded scenario (a build
    without one, as pythonfmu's own checks make, gets placeholders)."""
    try:
        doc = json.loads(Path(scenario_json).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return ModelMeta("canalnav navigation", 60.0)
    meta = doc.get("scenario", {})
    name = meta.get("name", "scenario")
    return ModelMeta(f"canalnav navigation for scenario {name!r}: simulated GPS/AHRS into an "
                     f"EKF, perception and the controller at 10 Hz; the boat's state in, "
                     f"throttle and steering out; step it at {IMU_PERIOD_S:g} s or a whole "
                     f"fraction of it", float(meta.get("duration_s", 60.0)))


def _base_units(name: str) -> dict:
    unit = UNITS[name]
    attrs = {k: str(v) for k, v in unit.base}
    if unit.factor != 1.0:
        attrs["factor"] = repr(unit.factor)
    return attrs


def unit_definitions_fmi2() -> Element:
    """<UnitDefinitions> of the FMU's units (FMI 2.0 and 3.0 share the layout)."""
    defs = Element("UnitDefinitions")
    for name in UNIT_NAMES:
        unit = SubElement(defs, "Unit", name=name)
        SubElement(unit, "BaseUnit", _base_units(name))
        display = UNITS[name].display
        if display:
            SubElement(unit, "DisplayUnit", name=display[0], factor=repr(display[1]))
    return defs
