"""`canalnav fmu system`: the boat FMU, the navigation FMU and their connections as an OSP
system structure (OspSystemStructure.xml) and an SSP package (system.ssp), to run as is."""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement, indent, tostring

from controller.errors import InputError
from controller.model import CURRENT_NAMES, INPUT_NAMES, STATE_NAMES
from controller.params import PARAM_NAMES
from scenarios.cosim.description import SYSTEM_STEP_S
from scenarios.cosim.nav_variables import (ACCEL_INPUTS, ACTUATOR_INPUTS, COMMAND_OUTPUTS,
                                           IMU_PERIOD_S, STATE_INPUTS)

OSP_FILE = "OspSystemStructure.xml"
SSP_FILE = "system.ssp"
BOAT, NAVIGATION = "boat", "navigation"  # the simulators' names, and their FMU files' stems
OSP_NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
BOAT_INTERNAL_STEP_S = 0.01  # as `canalnav run`'s FMU plant integrates


@dataclass(frozen=True)
class Connection:
    """One output of one simulator into one input of another."""

    source: str
    output: str
    target: str
    input: str


CONNECTIONS: tuple[Connection, ...] = (
    tuple(Connection(BOAT, n, NAVIGATION, n) for n in STATE_INPUTS + ACCEL_INPUTS
          + ACTUATOR_INPUTS)
    + tuple(Connection(NAVIGATION, n, BOAT, n) for n in COMMAND_OUTPUTS)
)


def check_step(step_s: float, source: str = "--step") -> float:
    """The communication step, or an InputError: it must divide the IMU period."""
    ratio = IMU_PERIOD_S / step_s if step_s > 0 else 0.0
    if not (step_s > 0 and abs(ratio - round(ratio)) < 1e-6):
        raise InputError(f"{source}: step {step_s:g} s: the navigation FMU needs a step that "
                         f"divides its IMU period {IMU_PERIOD_S:g} s (e.g. 0.01, 0.001, "
                         f"0.0005 s)")
    return step_s


def boat_initial_values(scenario) -> dict[str, float]:
    """The boat FMU's parameters and inputs for a scenario, as `canalnav run`'s plant sets them."""
    values = dict(zip(PARAM_NAMES, scenario.plant_params.as_vector()))
    values.update(zip((f"{n}0" for n in STATE_NAMES), map(float, scenario.initial_state)))
    values.update({f"{n}0": 0.0 for n in INPUT_NAMES})
    values.update(zip(CURRENT_NAMES, map(float, scenario.current_ne)))
    values.update(zip(("dnT_max", "dnS_max"), map(float, scenario.actuator_rates)))
    values["internal_step"] = BOAT_INTERNAL_STEP_S
    return {k: float(v) for k, v in values.items()}


def osp_xml(boat_values: dict[str, float], step_s: float) -> str:
    root = Element("OspSystemStructure", xmlns=OSP_NS, version="0.1")
    SubElement(root, "StartTime").text = "0.0"
    SubElement(root, "BaseStepSize").text = repr(step_s)
    SubElement(root, "Algorithm").text = "fixedStep"
    sims = SubElement(root, "Simulators")
    boat = SubElement(sims, "Simulator", name=BOAT, source=f"{BOAT}.fmu")
    initial = SubElement(boat, "InitialValues")
    for name, value in boat_values.items():
        SubElement(SubElement(initial, "InitialValue", variable=name), "Real",
                   value=repr(value))
    SubElement(sims, "Simulator", name=NAVIGATION, source=f"{NAVIGATION}.fmu")
    links = SubElement(root, "Connections")
    for c in CONNECTIONS:
        link = SubElement(links, "VariableConnection")
        SubElement(link, "Variable", simulator=c.source, name=c.output)
        SubElement(link, "Variable", simulator=c.target, name=c.input)
    indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, "unicode") + "\n"


_SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
_SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
_SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"


def ssd_xml(boat_values: dict[str, float], duration_s: float) -> str:
    """SystemStructure.ssd (SSP 1.0): the two components, the boat's parameter values, the
    connections and the default experiment."""
    root = Element("ssd:SystemStructureDescription", {
        "xmlns:ssd": _SSD, "xmlns:ssc": _SSC, "xmlns:ssv": _SSV, "version": "1.0",
        "name": "canalnav"})
    system = SubElement(root, "ssd:System", name="canalnav")
    elements = SubElement(system, "ssd:Elements")
    ports = {BOAT: {}, NAVIGATION: {}}
    for c in CONNECTIONS:
        ports[c.source][c.output] = "output"
        ports[c.target][c.input] = "input"
    for name in (BOAT, NAVIGATION):
        comp = SubElement(elements, "ssd:Component", name=name, source=f"resources/{name}.fmu",
                          type="application/x-fmu-sharedlibrary")
        conns = SubElement(comp, "ssd:Connectors")
        for port, kind in ports[name].items():
            SubElement(SubElement(conns, "ssd:Connector", name=port, kind=kind), "ssc:Real")
        if name == BOAT:
            binding = SubElement(SubElement(comp, "ssd:ParameterBindings"),
                                 "ssd:ParameterBinding")
            values = SubElement(binding, "ssd:ParameterValues")
            pset = SubElement(values, "ssv:ParameterSet", version="1.0", name="scenario")
            params = SubElement(pset, "ssv:Parameters")
            for var, value in boat_values.items():
                SubElement(SubElement(params, "ssv:Parameter", name=var), "ssv:Real",
                           value=repr(value))
    links = SubElement(system, "ssd:Connections")
    for c in CONNECTIONS:
        SubElement(links, "ssd:Connection", startElement=c.source, startConnector=c.output,
                   endElement=c.target, endConnector=c.input)
    SubElement(root, "ssd:DefaultExperiment", startTime="0.0", stopTime=repr(float(duration_s)))
    indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, "unicode") + "\n"


def write_system(scenario_path: str | Path, out_dir: str | Path, fmi_version: int = 2,
                 step_s: float = SYSTEM_STEP_S, overrides=()) -> dict[str, Path]:
    """Build both FMUs for a scenario file and write the system around them into `out_dir`:
    boat.fmu, navigation.fmu, OspSystemStructure.xml, system.ssp. Returns the paths by kind."""
    from fmu.build import build_fmu
    from scenarios.cosim.build import build_navigation_fmu, scenario_document
    from scenarios.scenario_file import scenario_from_table

    check_step(step_s)
    document = scenario_document(scenario_path, overrides)
    scenario = scenario_from_table(document, str(scenario_path))
    if scenario.current_profile is not None:
        raise InputError(f"{scenario_path}: field 'current.profile': a current that changes "
                         f"along the canal needs `canalnav run`; the co-simulation's boat takes "
                         f"one current")
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"-o {out}: cannot make the folder: {exc.strerror or exc}") from None
    boat = build_fmu(out / f"{BOAT}.fmu", fmi_version, scenario.plant_params)
    nav = build_navigation_fmu(scenario_path, out / f"{NAVIGATION}.fmu", fmi_version, overrides)
    values = boat_initial_values(scenario)
    osp = out / OSP_FILE
    osp.write_text(osp_xml(values, step_s), encoding="utf-8")
    ssp = out / SSP_FILE
    with zipfile.ZipFile(ssp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", ssd_xml(values, scenario.duration_s))
        z.write(boat, f"resources/{BOAT}.fmu")
        z.write(nav, f"resources/{NAVIGATION}.fmu")
    return {"boat": boat, "navigation": nav, "osp": osp, "ssp": ssp}
