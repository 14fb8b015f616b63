"""The navigation FMU in FMI 2.0 and 3.0: fmpy accepts both, every variable has a unit or a
description, and fmpy stepping it beside the boat FMU as a co-simulation master does (both
step, then the outputs go to the inputs) closes the loop of `canalnav run` to micrometres.
Each run of FMU instances is its own process (fmpy_master.py), as a tool loads an FMU."""

from dataclasses import replace

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from controller.errors import InputError
from scenarios.cosim.build import build_navigation_fmu
from scenarios.cosim.nav_variables import VARIABLES
from scenarios.loop.runner import run_scenario


@pytest.mark.parametrize("version", [2, 3])
def test_fmpy_validates_the_navigation_fmu(nav_fmus, version):
    assert validate_fmu(str(nav_fmus[version])) == []


@pytest.mark.parametrize("version", [2, 3])
def test_every_variable_has_a_description_and_every_real_a_unit(nav_fmus, version):
    md = read_model_description(str(nav_fmus[version]))
    assert md.defaultExperiment.stopTime == "110.0"
    assert float(md.defaultExperiment.stepSize) == 0.01
    assert "short-bend" in md.description
    ours = {v.name: v for v in VARIABLES}
    found = {v.name: v for v in md.modelVariables if v.name in ours}
    assert set(found) == set(ours)
    for name, var in found.items():
        assert var.description, name
        if ours[name].kind == "real":
            assert var.unit == ours[name].unit, name
    assert {u.name for u in md.unitDefinitions} >= {"m", "rad", "%", "m/s2"}


HELPER = Path(__file__).with_name("fmpy_master.py")


def _master(*args) -> dict:
    done = subprocess.run([sys.executable, str(HELPER), *map(str, args)], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("version", [2, 3])
def test_fmpy_with_both_fmus_closes_the_loop_of_canalnav_run(nav_fmus, short_bend,
                                                             short_bend_file, tmp_path, version):
    from fmu.build import build_fmu

    scenario = replace(short_bend, duration_s=4.0)
    run_scenario(scenario, tmp_path / "run", plots=False)
    log = np.genfromtxt(tmp_path / "run" / "log.csv", delimiter=",", names=True)
    boat = build_fmu(tmp_path / f"boat{version}.fmu", version, scenario.plant_params)
    ours = np.array(_master("loop", nav_fmus[version], boat, short_bend_file, 4.0,
                            tmp_path / "nav.csv")["states"])
    theirs = np.column_stack([log[f"true_{n}"] for n in
                              ("x_m", "y_m", "psi_rad", "u_mps", "v_mps", "r_radps")])
    assert ours[-1, 3] > 0.05  # the boat got going
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-5)
    rows = (tmp_path / "nav.csv").read_text().splitlines()
    assert len(rows) == 42 and rows[0].startswith("time_s,est_x_m")  # decisions 0.0 ... 4.0


def test_a_bad_step_is_an_fmi_error_with_the_reason_in_the_fmu_log(nav_fmus):
    out = _master("bad-step", nav_fmus[2])
    assert out["raised"]
    text = " ".join(m for _, m in out["messages"])
    assert "communication step 0.03 s" in text and "0.01 s" in text
    assert any(status >= 3 for status, _ in out["messages"])  # fmi2Error


def test_an_unknown_controller_parameter_fails_initialisation_with_its_reason(nav_fmus):
    out = _master("parameter", nav_fmus[2], "controller", "bogus")
    assert out["raised"]
    assert any("'bogus' is not available" in m for _, m in out["messages"])


def test_a_scenario_that_does_not_load_is_an_error_naming_it(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario]\nname = 'x'\n")
    with pytest.raises(InputError, match="bad.toml"):
        build_navigation_fmu(bad, tmp_path / "nav.fmu")
    with pytest.raises(InputError, match="no such scenario file"):
        build_navigation_fmu(tmp_path / "missing.toml", tmp_path / "nav.fmu")
    assert not (tmp_path / "nav.fmu").exists()


def test_a_missing_cosim_extra_is_named(monkeypatch, short_bend_file, tmp_path):
    monkeypatch.setitem(sys.modules, "pythonfmu3.builder", None)
    with pytest.raises(InputError, match=r"canalnav\[cosim\]"):
        build_navigation_fmu(short_bend_file, tmp_path / "nav.fmu", 3)
