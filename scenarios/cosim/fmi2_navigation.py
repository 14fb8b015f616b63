"""The navigation FMU's FMI 2.0 face (pythonfmu): variables from `nav_variables`, behaviour
from `nav_model`; pythonfmu's Real has no unit, so units are added to the description here."""

from __future__ import annotations

import sys
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import (DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer,
                       Real, String)
from pythonfmu.enums import Fmi2Status

from scenarios.cosim.description import describe_model, unit_definitions_fmi2
from scenarios.cosim.nav_model import SCENARIO_RESOURCE, NavigationModel
from scenarios.cosim.nav_variables import VARIABLES

_KINDS = {"real": Real, "integer": Integer, "string": String}
_PINNED: list = []
"""One reference to each instance, its class and its script module: pythonfmu 0.7's
fmi2FreeInstance drops one reference too many to them, which freed them while still in use:
the next instance in the process failed ("module has no attribute 'CanalnavNavigation'") and
the master crashed in Python's last garbage collection. An instance's memory is kept."""


class _UnitReal(Real):
    """A pythonfmu Real that writes its unit."""

    def __init__(self, name, unit: str = "", **kwargs):
        super().__init__(name, **kwargs)
        self._unit = unit

    def to_xml(self) -> Element:
        node = super().to_xml()
        if self._unit:
            node.find("Real").set("unit", self._unit)
        return node


class NavigationFmi2(Fmi2Slave):
    """canalnav's navigation stack (sensors, filter, perception, controller) for a scenario."""

    author = "canalnav"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        _PINNED.extend((self, type(self), sys.modules.get(type(self).__module__)))
        self.model = NavigationModel(self.resources)
        meta = describe_model(Path(self.resources or ".") / SCENARIO_RESOURCE)
        self.description = meta.description
        self.default_experiment = DefaultExperiment(0.0, meta.duration_s, meta.step_s)
        values = self.model.values
        for var in VARIABLES:
            kind = _KINDS[var.kind] if var.kind != "real" else _UnitReal
            extra = {"unit": var.unit} if var.kind == "real" else {}
            causality = getattr(Fmi2Causality, var.causality)
            variability = (Fmi2Variability.fixed if var.causality == "parameter" else
                           Fmi2Variability.discrete if var.causality == "output"
                           and var.kind != "real" else Fmi2Variability.continuous)
            self.register_variable(kind(
                var.name, causality=causality, variability=variability,
                description=var.description,
                getter=lambda n=var.name: values[n],
                setter=lambda x, n=var.name: values.__setitem__(n, x), **extra))

    def to_xml(self, model_options=dict()) -> Element:
        # pythonfmu 0.7 cannot load the class again once its binary was unloaded in the
        # process (instances while it stays loaded are fine): said as FMI 2.0 says it
        root = super().to_xml({**model_options, "canBeInstantiatedOnlyOncePerProcess": True})
        root.insert(1, unit_definitions_fmi2())
        structure = root.find("ModelStructure")
        outputs = structure.find("Outputs")
        initial = SubElement(structure, "InitialUnknowns")  # the outputs are calculated
        for unknown in outputs:  # and depend on no input within a step
            unknown.set("dependencies", "")
            SubElement(initial, "Unknown", index=unknown.get("index"), dependencies="")
        return root

    def exit_initialization_mode(self):
        reason = self.model.start()
        if reason is not None:
            self.log(reason, Fmi2Status.error)
            raise RuntimeError(reason)

    def do_step(self, current_time: float, step_size: float) -> bool:
        ok = self.model.step(current_time, step_size)
        if not ok:
            self.log(self.model.error, Fmi2Status.error)
        return ok

    def terminate(self):
        self.model.close()
