"""`canalnav fmu build-controller`: the navigation stack as a co-simulation FMU with its
scenario embedded (pythonfmu for FMI 2.0, pythonfmu3 for FMI 3.0)."""

from __future__ import annotations

import json
import shutil
import tempfile
import uuid
from pathlib import Path

from controller.errors import InputError
from scenarios.cosim.extra import require
from scenarios.cosim.nav_model import SCENARIO_RESOURCE

MODEL_IDENTIFIER = "CanalnavNavigation"
_WRAPPERS = {  # builder, its slave base class, our wrapper
    2: ("pythonfmu", "Fmi2Slave", "scenarios.cosim.fmi2_navigation", "NavigationFmi2"),
    3: ("pythonfmu3", "Fmi3Slave", "scenarios.cosim.fmi3_navigation", "NavigationFmi3")}


def scenario_document(path: str | Path, overrides=()) -> dict:
    """The scenario file's document with the (path, value) overrides applied, checked as
    `canalnav run` checks it (an InputError naming the file or the override otherwise)."""
    from scenarios.scenario_file import load_scenario, parse_toml
    from scenarios.studies.overrides import apply_overrides, scenario_with_overrides

    scenario = load_scenario(path)
    text = Path(path).read_text(encoding="utf-8")
    if overrides:
        scenario_with_overrides(text, str(path), overrides, path=scenario.path,
                                given_at=lambda p: f"--set {p}")
    document = apply_overrides(parse_toml(text, str(path)), overrides)
    try:
        json.dumps(document)
    except TypeError as exc:
        raise InputError(f"{path}: holds a value the FMU cannot embed ({exc}); give dates "
                         f"and times as strings") from None
    return document


def build_navigation_fmu(scenario_path: str | Path, out: str | Path, fmi_version: int = 2,
                         overrides=()) -> Path:
    """Build the navigation FMU for a scenario file into `out` (a .fmu path)."""
    if fmi_version not in _WRAPPERS:
        raise InputError(f"--fmi {fmi_version}: choose 2 or 3")
    package, base, module, wrapper = _WRAPPERS[fmi_version]
    builder = require(f"{package}.builder", f"the FMI {fmi_version}.0 navigation FMU")
    out = Path(out)
    if out.suffix != ".fmu":
        raise InputError(f"-o {out}: the FMU's file name must end in .fmu")
    document = scenario_document(scenario_path, overrides)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="canalnav-nav-fmu-") as tmp:
        # a module name of its own per build: several navigation FMUs (other scenarios, both
        # FMI versions) may run in one Python process, and a build beside them
        script = Path(tmp) / f"canalnav_navigation_fmi{fmi_version}_{uuid.uuid4().hex[:12]}.py"
        script.write_text(  # the builders look for the slave class in the script itself
            f'"""canalnav\'s navigation FMU (FMI {fmi_version}.0); its code is in the canalnav '
            f'package."""\nfrom {package} import {base}\nfrom {module} import {wrapper}\n\n\n'
            f"class {MODEL_IDENTIFIER}({wrapper}, {base}):\n"
            f'    """canalnav\'s navigation stack for the embedded scenario."""\n')
        scenario = Path(tmp) / SCENARIO_RESOURCE
        scenario.write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
        built = builder.FmuBuilder.build_FMU(script, dest=Path(tmp) / "fmu",
                                             project_files=[scenario])
        shutil.move(str(built), out)
    return out
