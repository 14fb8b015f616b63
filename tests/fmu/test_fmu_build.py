"""Building the FMUs: validation, archive layout, sources that compile elsewhere, the cache."""

import ctypes
import subprocess
import zipfile
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from bridge.main import main
from controller.errors import InputError
from controller.params import IDENTIFIED, PARAM_NAMES
from fmu import build
from fmu.check import check_fmu
from fmu.plant import FmuBoat
from fmu.variables import OUTPUT_NAMES, UNITS, VARIABLES, VR


def names(path):
    with zipfile.ZipFile(path) as z:
        return set(z.namelist())


def test_fmpy_validation_finds_no_problem(fmu_path):
    assert validate_fmu(str(fmu_path)) == []
    assert check_fmu(fmu_path) == []


def test_fmpy_simulate_runs_both(fmu_path):
    result = simulate_fmu(str(fmu_path), stop_time=30.0, output_interval=1.0,
                          start_values={"nT": 42.0, "nS": -20.0})
    assert result["time"][-1] == pytest.approx(30.0)
    assert result["u"][-1] > 1.0 and result["r"][-1] > 0  # nS < 0 turns to starboard


def test_archive_layout_and_platform_folders(fmus):
    two, three = names(fmus[2]), names(fmus[3])
    assert "binaries/linux64/canalnav_boat.so" in two
    assert "binaries/x86_64-linux/canalnav_boat.so" in three
    assert "sources/buildDescription.xml" in three and "sources/buildDescription.xml" not in two
    for files in (two, three):
        assert not any(n.split("/")[-1].startswith(("fmi2", "fmi3")) and n.endswith(".h")
                       for n in files), "the FMI headers must not be shipped"


def test_listed_sources_exist_and_compile_alone(fmus, tmp_path):
    """What a tool on another platform does: compile exactly the listed files."""
    for version, path in fmus.items():
        with zipfile.ZipFile(path) as z:
            z.extractall(tmp_path / f"v{version}")
        root = tmp_path / f"v{version}"
        if version == 2:
            md = ET.parse(root / "modelDescription.xml").getroot()
            listed = [f.get("name") for f in md.iter("File")]
        else:
            bd = ET.parse(root / "sources" / "buildDescription.xml").getroot()
            listed = [f.get("name") for f in bd.iter("SourceFile")]
        assert listed and all((root / "sources" / n).is_file() for n in listed)
        lib = tmp_path / f"again{version}.so"
        subprocess.run(["gcc", "-std=c99", "-shared", "-fPIC", "-fvisibility=hidden",
                        f"-I{root / 'sources'}", f"-I{build.fmi_headers_dir()}", "-o", str(lib),
                        *(str(root / "sources" / n) for n in listed), "-lm"], check=True)
        dll = ctypes.CDLL(str(lib))
        get_version = getattr(dll, f"fmi{version}GetVersion")
        get_version.restype = ctypes.c_char_p
        assert get_version().decode() == f"{version}.0"


def test_every_variable_has_a_declared_unit_and_legal_kind(fmu_path):
    md = read_model_description(str(fmu_path))
    declared = {u.name for u in md.unitDefinitions}
    legal = {("independent", "continuous", None), ("input", "continuous", "exact"),
             ("output", "continuous", "calculated"), ("parameter", "fixed", "exact"),
             ("parameter", "tunable", "exact")}
    for v in md.modelVariables:
        assert v.unit in declared, v.name
        assert (v.causality, v.variability, v.initial) in legal, v.name
        assert (v.start is None) == (v.causality in ("output", "independent")), v.name
    assert {v.name for v in md.modelVariables if v.causality == "parameter"
            and v.variability == "tunable"} >= set(PARAM_NAMES)
    assert md.modelVariables[VR["delta_max"]].unit == "rad"
    assert md.modelVariables[VR["delta_max"]].displayUnit == "deg"


def test_both_versions_declare_the_same_table(fmus):
    two = read_model_description(str(fmus[2])).modelVariables
    three = read_model_description(str(fmus[3])).modelVariables
    assert [(v.name, v.valueReference, v.unit, v.causality, v.start) for v in two] == \
           [(v.name, v.valueReference, v.unit, v.causality, v.start) for v in three]
    assert [v.name for v in two] == [v.name for v in VARIABLES]


def test_initial_unknowns_are_the_outputs_with_their_true_dependencies(fmu_path):
    md = read_model_description(str(fmu_path))
    unknowns = {u.variable.name: u for u in md.initialUnknowns}
    assert set(unknowns) == set(OUTPUT_NAMES)
    assert all(o.dependencies == [] for o in md.outputs)  # no direct feedthrough
    # the declared dependencies match what the FMU computes: perturb each known in turn
    knowns = [v.name for v in md.modelVariables if v.causality in ("parameter", "input")]
    base = FmuBoat(fmu_path)
    state0 = dict(psi0=0.4, u0=1.0, v0=0.1, r0=0.05, nT0=40.0, nS0=10.0)
    base.set_values(state0)
    y0 = base.get_values(OUTPUT_NAMES)  # initialization values before any step
    for known in knowns:
        boat = FmuBoat(fmu_path)
        boat.set_values(state0)
        value = state0.get(known, boat.get_values([known])[0])
        boat.set_values({known: value * 1.1 + 0.5})
        changed = boat.get_values(OUTPUT_NAMES) != y0
        for i, name in enumerate(OUTPUT_NAMES):
            declared = {d.name for d in (unknowns[name].dependencies or [])}
            if changed[i]:
                assert known in declared, f"{name} depends on {known} but does not say so"
        boat.close()
    base.close()


def test_params_file_sets_start_values(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    toml = tmp_path / "p.toml"
    IDENTIFIED.replace(m11=2500.0, delta_max=0.5).save_toml(toml)
    out = tmp_path / "custom.fmu"
    assert main(["fmu", "build", "--fmi-version", "3", "--params", str(toml), "-o", str(out)]) == 0
    md = read_model_description(str(out))
    start = {v.name: v.start for v in md.modelVariables}
    assert float(start["m11"]) == 2500.0 and float(start["delta_max"]) == pytest.approx(0.5)
    with FmuBoat(out) as boat:
        boat.setup()
        assert boat.get_values(["m11"])[0] == 2500.0


def test_cache_skips_the_compiler_and_tracks_parameters(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    first = build.build_fmu(tmp_path / "a.fmu", 2)
    assert list((tmp_path / "cache" / "canalnav" / "fmu").glob("*.fmu"))

    def no_compiler(*args, **kwargs):
        raise AssertionError("compiled although an identical build is cached")

    monkeypatch.setattr(build, "compile_shared_library", no_compiler)
    second = build.build_fmu(tmp_path / "b.fmu", 2)
    assert first.read_bytes() == second.read_bytes()
    with pytest.raises(AssertionError, match="compiled"):
        build.build_fmu(tmp_path / "c.fmu", 2, IDENTIFIED.replace(m22=2000.0))


def test_build_rejects_bad_version_and_missing_params(tmp_path, capsys):
    with pytest.raises(InputError, match="fmi-version"):
        build.build_fmu(tmp_path / "x.fmu", 4)
    assert main(["fmu", "build", "--params", str(tmp_path / "none.toml")]) == 2
    assert "none.toml" in capsys.readouterr().err


def test_check_rejects_missing_and_broken_files(tmp_path, capsys):
    assert main(["fmu", "check", str(tmp_path / "none.fmu")]) == 2
    broken = tmp_path / "broken.fmu"
    broken.write_text("not a zip")
    assert main(["fmu", "check", str(broken)]) == 2
    err = capsys.readouterr().err
    assert "none.fmu" in err and "broken.fmu" in err and "Traceback" not in err


def test_check_reports_a_validation_problem(fmus, tmp_path):
    """A modelDescription with an illegal causality/variability pair is reported."""
    bad = tmp_path / "bad.fmu"
    with zipfile.ZipFile(fmus[2]) as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item == "modelDescription.xml":
                data = data.replace(b'causality="input" variability="continuous"',
                                    b'causality="input" variability="fixed"', 1)
            dst.writestr(item, data)
    problems = check_fmu(bad)
    assert problems and any("illegal combination" in p and "nT" in p for p in problems)


def test_outputs_vector_order_matches_names():
    assert OUTPUT_NAMES == ("x", "y", "psi", "u", "v", "r", "u_dot", "v_dot", "r_dot",
                            "nT_actual", "nS_actual")
    assert all(UNITS[v.unit] for v in VARIABLES)
    assert np.all(np.diff([VR[n] for n in OUTPUT_NAMES]) == 1)


def test_fmpy_compiles_the_sources_without_our_binary(fmus, tmp_path):
    """fmpy's CMake build (`fmpy compile`, what a tool on another platform does) from the
    shipped sources alone gives an FMU that runs the same."""
    import sys
    from pathlib import Path

    fmpy_cli = Path(sys.executable).with_name("fmpy")
    for version, path in fmus.items():
        source_only = tmp_path / f"source{version}.fmu"
        with zipfile.ZipFile(path) as src, zipfile.ZipFile(source_only, "w") as dst:
            for item in src.namelist():
                if not item.startswith("binaries/"):
                    dst.writestr(item, src.read(item))
        subprocess.run([str(fmpy_cli), "compile", str(source_only)], check=True,
                       capture_output=True)
        assert any(n.startswith(f"binaries/{build.platform_folder(version)}/")
                   for n in names(source_only))
        runs = [simulate_fmu(str(p), stop_time=20.0, output_interval=1.0,
                             start_values={"nT": 42.0, "nS": 30.0})
                for p in (path, source_only)]
        assert np.allclose(runs[0]["y"], runs[1]["y"], rtol=1e-12, atol=1e-12)


def test_lifecycle_check_notices_a_state_that_does_not_restore(fmus, monkeypatch):
    from fmu import check

    assert check.lifecycle_problems(fmus[3]) == []
    monkeypatch.setattr(FmuBoat, "set_state", lambda self, state: None)
    problems = check.lifecycle_problems(fmus[3])
    assert any("get/set FMU state" in p for p in problems)


def test_the_readmes_fmpy_example_writes_its_output(fmus, tmp_path):
    """Issue 35: the README's `fmpy simulate boat.fmu ...` printed and wrote nothing. Each
    `fmpy` line of fmu/README.md, run on the built FMU, writes the file it names."""
    import re
    import shlex
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[2] / "fmu" / "README.md").read_text()
    lines = [ln for block in re.findall(r"```sh\n(.*?)```", readme, re.S)
             for ln in block.splitlines() if ln.startswith("fmpy ")]
    assert lines
    shutil.copy(fmus[3], tmp_path / "boat.fmu")
    for line in lines:
        words = shlex.split(line)
        assert "--output-file" in words, f"{line}: writes nothing"
        out = tmp_path / words[words.index("--output-file") + 1]
        exe = Path(sys.executable).with_name("fmpy")
        subprocess.run([str(exe), *words[1:]], cwd=tmp_path, check=True, timeout=120,
                       capture_output=True)
        rows = out.read_text().splitlines()
        assert rows[0].startswith('"time"') and len(rows) > 50, line
