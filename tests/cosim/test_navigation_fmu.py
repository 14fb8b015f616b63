"""The navigation FMU in FMI 2.0 and 3.0: fmpy accepts both, every variable has a unit or a
description, and fmpy stepping it beside the boat FMU (navigation first, its command to the
boat in the same step) closes the same loop as `canalnav run`, bit for bit."""

import ctypes
import shutil
from dataclasses import replace

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.validation import validate_fmu

from controller.errors import InputError
from scenarios.cosim.build import build_navigation_fmu
from scenarios.cosim.nav_variables import VARIABLES
from scenarios.cosim.system import boat_initial_values
from scenarios.loop.runner import run_scenario


@pytest.mark.parametrize("version", [2, 3])
def test_fmpy_validates_the_navigation_fmu(nav_fmus, version):
    assert validate_fmu(str(nav_fmus[version])) == []


@pytest.mark.parametrize("version", [2, 3])
def test_every_variable_has_a_description_and_every_real_a_unit(nav_fmus, version):
    md = read_model_description(str(nav_fmus[version]))
    assert md.defaultExperiment.stopTime == "110.0"
    assert float(md.defaultExperiment.stepSize) == 0.0005
    assert "short-bend" in md.description
    ours = {v.name: v for v in VARIABLES}
    found = {v.name: v for v in md.modelVariables if v.name in ours}
    assert set(found) == set(ours)
    for name, var in found.items():
        assert var.description, name
        if ours[name].kind == "real":
            assert var.unit == ours[name].unit, name
    assert {u.name for u in md.unitDefinitions} >= {"m", "rad", "%", "m/s2"}


def _boat_fmu(tmp_path, version, scenario):
    from fmu.build import build_fmu

    return build_fmu(tmp_path / f"boat{version}.fmu", version, scenario.plant_params)


class _Fmu:
    """An FMU instance in fmpy, values by name, its log messages kept."""

    def __init__(self, path, name, messages=None):
        from fmpy import instantiate_fmu

        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.dir = extract(str(path))
        self.messages = messages
        kwargs = {}
        if messages is not None and self.md.fmiVersion == "2.0":
            from fmpy.fmi2 import (fmi2CallbackFunctions, fmi2CallbackLoggerTYPE,
                                   fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE)
            from fmpy import calloc, free

            def logger(env, instance, status, category, message):
                messages.append((status, message.decode()))

            cb = fmi2CallbackFunctions()
            cb.logger = fmi2CallbackLoggerTYPE(logger)
            cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            self._callbacks = cb
            kwargs = {"fmi_call_logger": None}
        self.fmu = instantiate_fmu(self.dir, self.md, fmi_type="CoSimulation",
                                   **({} if not kwargs else {}))
        if messages is not None and self.md.fmiVersion == "2.0":
            self.fmu.freeInstance()
            from fmpy.fmi2 import FMU2Slave

            self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                                 modelIdentifier=self.md.coSimulation.modelIdentifier,
                                 instanceName=name)
            self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        self.v3 = self.md.fmiVersion == "3.0"

    def set(self, **values):
        for name, value in values.items():
            if isinstance(value, str):
                self.fmu.setString([self.vr[name]], [value])
            elif isinstance(value, int) and not isinstance(value, bool):
                (self.fmu.setInt32 if self.v3 else self.fmu.setInteger)([self.vr[name]], [value])
            else:
                (self.fmu.setFloat64 if self.v3 else self.fmu.setReal)([self.vr[name]],
                                                                       [float(value)])

    def get(self, *names):
        get = self.fmu.getFloat64 if self.v3 else self.fmu.getReal
        return np.array(get([self.vr[n] for n in names]), float)

    def init(self):
        if self.v3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()
        shutil.rmtree(self.dir, ignore_errors=True)


BOAT_OUT = ("x", "y", "psi", "u", "v", "r", "u_dot", "v_dot", "r_dot", "nT_actual",
            "nS_actual")


@pytest.mark.parametrize("version", [2, 3])
def test_fmpy_with_both_fmus_closes_the_loop_of_canalnav_run(nav_fmus, short_bend, tmp_path,
                                                             version):
    scenario = replace(short_bend, duration_s=4.0)
    run_scenario(scenario, tmp_path / "run", plots=False)
    log = np.genfromtxt(tmp_path / "run" / "log.csv", delimiter=",", names=True)
    boat = _Fmu(_boat_fmu(tmp_path, version, scenario), "boat")
    nav = _Fmu(nav_fmus[version], "navigation")
    boat.set(**boat_initial_values(scenario))
    boat.init()
    nav.set(**dict(zip(BOAT_OUT, boat.get(*BOAT_OUT))), log_path=str(tmp_path / "nav.csv"))
    nav.init()
    states = []
    h = 0.01
    for i in range(400):  # the navigation first: its command goes to the boat in this step
        t = i * h
        nav.set(**dict(zip(BOAT_OUT, boat.get(*BOAT_OUT))))
        nav.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        if i % 10 == 0:
            states.append(boat.get("x", "y", "psi", "u", "v", "r"))
        boat.set(**dict(zip(("nT", "nS"), nav.get("nT", "nS"))))
        boat.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
    nav.close()
    boat.close()
    theirs = np.column_stack([log[f"true_{n}"] for n in
                              ("x_m", "y_m", "psi_rad", "u_mps", "v_mps", "r_radps")])
    np.testing.assert_array_equal(np.array(states), theirs)
    rows = (tmp_path / "nav.csv").read_text().splitlines()
    assert len(rows) == 41 and rows[0].startswith("time_s,est_x_m")


def test_a_bad_step_is_an_fmi_error_with_the_reason_in_the_fmu_log(nav_fmus, tmp_path):
    messages = []
    nav = _Fmu(nav_fmus[2], "navigation", messages)
    nav.init()
    with pytest.raises(Exception):
        nav.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.03)
    text = " ".join(m for _, m in messages)
    assert "communication step 0.03 s" in text and "0.01 s" in text
    assert any(status >= 3 for status, _ in messages)  # fmi2Error
    nav.close()


def test_an_unknown_controller_parameter_fails_initialisation_with_its_reason(nav_fmus):
    messages = []
    nav = _Fmu(nav_fmus[2], "navigation", messages)
    nav.set(controller="bogus")
    with pytest.raises(Exception):
        nav.init()
    assert any("'bogus' is not available" in m for _, m in messages)
    nav.fmu.freeInstance()


def test_a_scenario_that_does_not_load_is_an_error_naming_it(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario]\nname = 'x'\n")
    with pytest.raises(InputError, match="bad.toml"):
        build_navigation_fmu(bad, tmp_path / "nav.fmu")
    with pytest.raises(InputError, match="no such scenario file"):
        build_navigation_fmu(tmp_path / "missing.toml", tmp_path / "nav.fmu")
    assert not (tmp_path / "nav.fmu").exists()


def test_a_missing_cosim_extra_is_named(monkeypatch, short_bend_file, tmp_path):
    import sys

    monkeypatch.setitem(sys.modules, "pythonfmu3.builder", None)
    with pytest.raises(InputError, match=r"canalnav\[cosim\]"):
        build_navigation_fmu(short_bend_file, tmp_path / "nav.fmu", 3)
