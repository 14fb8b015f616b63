"""The navigation FMU's FMI 3.0 face (pythonfmu3): the same variables and behaviour as the
FMI 2.0 one, with FMI 3.0's types (Float64, Int32, String)."""

from __future__ import annotations

from pathlib import Path
from xml.etree.ElementTree import Element

from pythonfmu3 import (DefaultExperiment, Fmi3Causality, Fmi3Slave, Fmi3Status, Fmi3Variability,
                        Float64, Int32, String)

from scenarios.cosim.description import describe_model, unit_definitions_fmi2
from scenarios.cosim.nav_model import SCENARIO_RESOURCE, NavigationModel
from scenarios.cosim.nav_variables import VARIABLES

_KINDS = {"real": Float64, "integer": Int32, "string": String}


class NavigationFmi3(Fmi3Slave):
    """canalnav's navigation stack (sensors, filter, perception, controller) for a scenario."""

    author = "canalnav"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.model = NavigationModel(self.resources)
        meta = describe_model(Path(self.resources or ".") / SCENARIO_RESOURCE)
        self.description = meta.description
        self.default_experiment = DefaultExperiment(0.0, meta.duration_s, meta.step_s)
        values = self.model.values
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous,
                                       description="simulation time", unit="s",
                                       getter=lambda: values.get("time", 0.0)))
        for var in VARIABLES:
            extra = {"unit": var.unit} if var.kind == "real" else {}
            variability = (Fmi3Variability.fixed if var.causality == "parameter" else
                           Fmi3Variability.discrete if var.causality == "output"
                           and var.kind != "real" else Fmi3Variability.continuous)
            self.register_variable(_KINDS[var.kind](
                var.name, causality=getattr(Fmi3Causality, var.causality),
                variability=variability, description=var.description,
                getter=lambda n=var.name: values[n],
                setter=lambda x, n=var.name: values.__setitem__(n, x), **extra))

    def to_xml(self, model_options=dict()) -> Element:
        root = super().to_xml(model_options)
        root.insert(1, unit_definitions_fmi2())
        return root

    def exit_initialization_mode(self):
        reason = self.model.start()
        if reason is not None:
            self.log(reason, Fmi3Status.error)
            raise RuntimeError(reason)

    def do_step(self, current_time: float, step_size: float) -> bool:
        self.model.values["time"] = current_time + step_size
        ok = self.model.step(current_time, step_size)
        if not ok:
            self.log(self.model.error, Fmi3Status.error)
        return ok

    def terminate(self):
        self.model.close()
