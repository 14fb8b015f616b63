"""modelDescription.xml for FMI 2.0 and 3.0, and FMI 3.0's buildDescription.xml, from one table.

Both versions declare the same variables, units and structure; only the XML dialect differs.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from xml.sax.saxutils import quoteattr

from .variables import UNITS, VR, Variable, dependencies_at_initialization

MODEL_IDENTIFIER = "canalnav_boat"
MODEL_NAME = "canalnav boat"
DESCRIPTION = ("3-DOF boat in a canal (paper model, exact |z| terms) with water current and "
               "actuator rate limits; fixed-step RK4 inside doStep")
LOG_CATEGORIES = (
    ("logStatusError", "errors: bad values, wrong calling sequence, failed steps (always on)"),
    ("logStatusWarning", "warnings"),
    ("logCalls", "every FMI call with its arguments"),
)


@dataclass(frozen=True)
class Experiment:
    start_time: float = 0.0
    stop_time: float = 300.0
    step_size: float = 0.1


def _num(x: float) -> str:
    return repr(float(x))


def _attrs(**kw) -> str:
    return "".join(f" {k}={quoteattr(str(v))}" for k, v in kw.items() if v is not None)


def _unit_definitions() -> list[str]:
    out = ["  <UnitDefinitions>"]
    for unit in UNITS.values():
        base = dict(unit.base)
        if unit.factor != 1.0:
            base["factor"] = _num(unit.factor)
        out.append(f"    <Unit{_attrs(name=unit.name)}>")
        out.append(f"      <BaseUnit{_attrs(**{k: str(v) for k, v in base.items()})}/>")
        if unit.display:
            name, factor = unit.display
            out.append(f"      <DisplayUnit{_attrs(name=name, factor=_num(factor))}/>")
        out.append("    </Unit>")
    out.append("  </UnitDefinitions>")
    return out


def _log_categories() -> list[str]:
    return (["  <LogCategories>"]
            + [f"    <Category{_attrs(name=n, description=d)}/>" for n, d in LOG_CATEGORIES]
            + ["  </LogCategories>"])


def _value_attrs(v: Variable) -> dict:
    return dict(
        unit=v.unit, displayUnit=v.display_unit,
        min=None if v.min is None else _num(v.min), max=None if v.max is None else _num(v.max),
        start=None if v.start is None else _num(v.start),
    )


def _header(version: str, token_attr: str, token: str) -> list[str]:
    stamp = datetime.now(timezone.utc).replace(microsecond=0).isoformat().replace("+00:00", "Z")
    return [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f"<fmiModelDescription{_attrs(fmiVersion=version, modelName=MODEL_NAME)}"
        f"{_attrs(**{token_attr: token})}{_attrs(description=DESCRIPTION)}"
        f"{_attrs(generationTool='canalnav', generationDateAndTime=stamp)}"
        ' variableNamingConvention="flat">',
    ]


def _experiment(e: Experiment) -> str:
    attrs = _attrs(startTime=_num(e.start_time), stopTime=_num(e.stop_time),
                   stepSize=_num(e.step_size))
    return f"  <DefaultExperiment{attrs}/>"


def fmi2_xml(table: tuple[Variable, ...], guid: str, source_files: list[str],
             experiment: Experiment = Experiment()) -> str:
    """FMI 2.0 co-simulation modelDescription.xml; sources listed in <SourceFiles>."""
    out = _header("2.0", "guid", guid)
    out.append(
        f"  <CoSimulation{_attrs(modelIdentifier=MODEL_IDENTIFIER)}"
        ' canHandleVariableCommunicationStepSize="true" canInterpolateInputs="false"'
        ' canGetAndSetFMUstate="true" canSerializeFMUstate="true"'
        ' canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="true"'
        ' needsExecutionTool="false" providesDirectionalDerivative="false">')
    out.append("    <SourceFiles>")
    out += [f"      <File{_attrs(name=f)}/>" for f in source_files]
    out.append("    </SourceFiles>")
    out.append("  </CoSimulation>")
    out += _unit_definitions()
    out += _log_categories()
    out.append(_experiment(experiment))
    out.append("  <ModelVariables>")
    for i, v in enumerate(table):
        out.append(f"    <!-- index {i + 1} -->")
        out.append(
            f"    <ScalarVariable{_attrs(name=v.name, valueReference=VR[v.name])}"
            f"{_attrs(description=v.description, causality=v.causality)}"
            f"{_attrs(variability=v.variability, initial=v.initial)}>")
        out.append(f"      <Real{_attrs(**_value_attrs(v))}/>")
        out.append("    </ScalarVariable>")
    out.append("  </ModelVariables>")
    index = {v.name: i + 1 for i, v in enumerate(table)}
    outputs = [v for v in table if v.causality == "output"]
    out.append("  <ModelStructure>")
    out.append("    <Outputs>")
    out += [f'      <Unknown index="{index[v.name]}" dependencies=""/>' for v in outputs]
    out.append("    </Outputs>")
    out.append("    <InitialUnknowns>")
    for v in outputs:
        deps = " ".join(str(index[d]) for d in sorted(dependencies_at_initialization(v),
                                                     key=index.get))
        kinds = " ".join("dependent" for _ in dependencies_at_initialization(v))
        out.append(f'      <Unknown index="{index[v.name]}" dependencies="{deps}"'
                   f' dependenciesKind="{kinds}"/>')
    out.append("    </InitialUnknowns>")
    out.append("  </ModelStructure>")
    out.append("</fmiModelDescription>")
    return "\n".join(out) + "\n"


def fmi3_xml(table: tuple[Variable, ...], token: str,
             experiment: Experiment = Experiment()) -> str:
    """FMI 3.0 co-simulation modelDescription.xml (sources go to buildDescription.xml)."""
    out = _header("3.0", "instantiationToken", token)
    out.append(
        f"  <CoSimulation{_attrs(modelIdentifier=MODEL_IDENTIFIER)}"
        ' canHandleVariableCommunicationStepSize="true" canGetAndSetFMUState="true"'
        ' canSerializeFMUState="true" canBeInstantiatedOnlyOncePerProcess="false"'
        ' needsExecutionTool="false" providesDirectionalDerivatives="false"'
        ' providesAdjointDerivatives="false" hasEventMode="false"'
        ' providesIntermediateUpdate="false" canReturnEarlyAfterIntermediateUpdate="false"/>')
    out += _unit_definitions()
    out += _log_categories()
    out.append(_experiment(experiment))
    out.append("  <ModelVariables>")
    for v in table:
        out.append(
            f"    <Float64{_attrs(name=v.name, valueReference=VR[v.name])}"
            f"{_attrs(description=v.description, causality=v.causality)}"
            f"{_attrs(variability=v.variability, initial=v.initial)}"
            f"{_attrs(**_value_attrs(v))}/>")
    out.append("  </ModelVariables>")
    outputs = [v for v in table if v.causality == "output"]
    out.append("  <ModelStructure>")
    out += [f'    <Output valueReference="{VR[v.name]}" dependencies=""/>' for v in outputs]
    for v in outputs:
        deps = " ".join(str(VR[d]) for d in sorted(dependencies_at_initialization(v),
                                                  key=VR.get))
        kinds = " ".join("dependent" for _ in dependencies_at_initialization(v))
        out.append(f'    <InitialUnknown valueReference="{VR[v.name]}" dependencies="{deps}"'
                   f' dependenciesKind="{kinds}"/>')
    out.append("  </ModelStructure>")
    out.append("</fmiModelDescription>")
    return "\n".join(out) + "\n"


def build_description_xml(source_files: list[str]) -> str:
    """FMI 3.0 sources/buildDescription.xml: what to compile (C99, libm) for another platform."""
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           '<fmiBuildDescription fmiVersion="3.0">',
           f"  <BuildConfiguration{_attrs(modelIdentifier=MODEL_IDENTIFIER)}"
           ' description="compile every listed file; the fmi3 headers come from the tool">',
           '    <SourceFileSet language="C99">']
    out += [f"      <SourceFile{_attrs(name=f)}/>" for f in source_files]
    out += ['      <IncludeDirectory name="."/>',
            "    </SourceFileSet>",
            '    <Library name="m" description="C math library"/>',
            "  </BuildConfiguration>",
            "</fmiBuildDescription>"]
    return "\n".join(out) + "\n"
