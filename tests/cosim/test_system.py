"""`canalnav fmu system` and `canalnav cosim`: the folder holds both FMUs, an OSP system
structure and an SSP package that libcosim runs as they are; the closed loop through libcosim
follows `canalnav run`; bad systems are refused by name before anything runs."""

import json
import shutil
import subprocess
import sys
import zipfile
from dataclasses import replace
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest

from bridge.main import main
from controller.errors import InputError
from scenarios.cosim.run import load_system
from scenarios.cosim.system import CONNECTIONS, write_system
from scenarios.loop.runner import run_scenario

OSP = "{http://opensimulationplatform.com/MSMI/OSPSystemStructure}"
SSD = "{http://ssp-standard.org/SSP1/SystemStructureDescription}"
CANALNAV = Path(sys.executable).with_name("canalnav")


def test_the_folder_holds_both_fmus_the_osp_structure_and_the_ssp(system_dir, short_bend):
    assert {p.name for p in system_dir.iterdir()} >= {"boat.fmu", "navigation.fmu",
                                                     "OspSystemStructure.xml", "system.ssp"}
    root = ElementTree.parse(system_dir / "OspSystemStructure.xml").getroot()
    assert float(root.findtext(f"{OSP}BaseStepSize")) == 0.01
    links = [[(v.get("simulator"), v.get("name")) for v in c]
             for c in root.iter(f"{OSP}VariableConnection")]
    assert [("boat", "x"), ("navigation", "x")] in links
    assert [("navigation", "nS"), ("boat", "nS")] in links
    assert len(links) == len(CONNECTIONS) == 13
    initial = {v.get("variable"): float(v.find(f"{OSP}Real").get("value"))
               for v in root.iter(f"{OSP}InitialValue")}
    assert initial["dnT_max"] == short_bend.actuator_rates[0] and initial["internal_step"] == 0.01
    with zipfile.ZipFile(system_dir / "system.ssp") as z:
        assert set(z.namelist()) == {"SystemStructure.ssd", "resources/boat.fmu",
                                     "resources/navigation.fmu"}
        ssd = ElementTree.fromstring(z.read("SystemStructure.ssd"))
    assert len(list(ssd.iter(f"{SSD}Component"))) == 2
    assert len(list(ssd.iter(f"{SSD}Connection"))) == 13


SSP_CHECK = """
import json, sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimObserver import CosimObserver

def check(path):  # the execution ends with the function, before Python's own teardown
    execution = CosimExecution.from_ssp_file(path, step_size=10_000_000)
    index = {s.name.decode(): s.index for s in execution.slave_infos()}
    refs = {v.name.decode(): v.reference for v in execution.slave_variables(index["boat"])}
    watch = CosimObserver.create_last_value()
    execution.add_observer(watch)
    ok = execution.step(50)
    names = ["dnT_max", "internal_step", "nT"]
    return [ok, watch.last_real_values(index["boat"], [refs[n] for n in names])]

print("RESULT", json.dumps(check(sys.argv[1])))
"""


def test_libcosim_runs_the_ssp_package_with_the_boats_parameters(system_dir, short_bend):
    done = subprocess.run([sys.executable, "-c", SSP_CHECK, str(system_dir / "system.ssp")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    line = next(x for x in done.stdout.splitlines() if x.startswith("RESULT "))
    ok, (rate, step, nT) = json.loads(line.removeprefix("RESULT "))
    assert ok  # 0.5 s of the two FMUs, as the package says, with no code of ours
    assert (rate, step) == (short_bend.actuator_rates[0], 0.01)
    assert nT > 0  # the navigation's throttle reached the boat


def test_a_step_the_controller_cannot_keep_is_refused_before_the_run(short_bend_file, system_dir,
                                                                      tmp_path):
    with pytest.raises(InputError, match="step 0.003 s.*0.01 s"):
        write_system(short_bend_file, tmp_path / "s", step_s=0.003)
    copy = shutil.copytree(system_dir, tmp_path / "copy")
    osp = copy / "OspSystemStructure.xml"
    osp.write_text(osp.read_text().replace("<BaseStepSize>0.01<", "<BaseStepSize>0.02<"))
    with pytest.raises(InputError, match="BaseStepSize: step 0.02 s"):
        load_system(copy)


def test_connections_the_boat_fmu_does_not_match_are_refused_by_name(system_dir, tmp_path):
    copy = shutil.copytree(system_dir, tmp_path / "copy")
    osp = copy / "OspSystemStructure.xml"
    osp.write_text(osp.read_text().replace('simulator="boat" name="u_dot"',
                                           'simulator="boat" name="surge_accel"'))
    with pytest.raises(InputError, match="'surge_accel' of 'boat'.*boat.fmu"):
        load_system(copy)
    shutil.copy(system_dir / "OspSystemStructure.xml", osp)
    shutil.copy(system_dir / "navigation.fmu", copy / "boat.fmu")  # a boat of other variables
    with pytest.raises(InputError, match="boat.x as an output.*declares it input"):
        load_system(copy)


def test_an_fmi3_system_is_written_and_refused_by_libcosim_by_name(short_bend_file, tmp_path):
    write_system(short_bend_file, tmp_path / "s3", fmi_version=3)
    with pytest.raises(InputError, match="FMI 3.0: libcosim runs FMI 2.0"):
        load_system(tmp_path / "s3")


def _states(log_path, names=("x_m", "y_m", "psi_rad", "u_mps", "v_mps", "r_radps")):
    log = np.genfromtxt(log_path, delimiter=",", names=True)
    return np.column_stack([log[f"true_{n}"] for n in names])


def test_canalnav_cosim_follows_canalnav_run(system_dir, short_bend, tmp_path):
    done = subprocess.run([str(CANALNAV), "cosim", str(system_dir), "--out",
                           str(tmp_path / "cosim"), "--duration", "5"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 1, done.stderr  # the goal is not reached in 5 s
    assert "criterion failed: did not reach the goal (time limit" in done.stdout
    summary = json.loads((tmp_path / "cosim" / "summary.json").read_text())
    assert summary["status"] == "time limit" and summary["steps"] == 50
    assert summary["min_clearance_m"] > 3.0 and summary["cosim"]["step_s"] == 0.01
    assert (tmp_path / "cosim" / "navigation_log.csv").read_text().count("\n") >= 51
    run_scenario(replace(short_bend, duration_s=5.0), tmp_path / "run", plots=False)
    ours, theirs = _states(tmp_path / "cosim" / "log.csv"), _states(tmp_path / "run" / "log.csv")
    assert ours.shape == theirs.shape == (50, 6) and ours[-1, 3] > 0.1
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-5)


def test_build_controller_and_system_commands(short_bend_file, tmp_path, capsys):
    assert main(["fmu", "build-controller", str(short_bend_file), "-o",
                 str(tmp_path / "nav.fmu"), "--fmi", "3",
                 "--set", "controller.d_p_m=2.5"]) == 0
    assert "FMI 3.0" in capsys.readouterr().out
    with zipfile.ZipFile(tmp_path / "nav.fmu") as z:
        embedded = json.loads(z.read("resources/scenario.json"))
    assert embedded["controller"]["d_p_m"] == 2.5
    assert main(["fmu", "system", str(short_bend_file), "-o", str(tmp_path / "sys")]) == 0
    assert (tmp_path / "sys" / "system.ssp").is_file()
    assert main(["fmu", "build-controller", str(tmp_path / "none.toml")]) == 2
    assert "none.toml: no such scenario file" in capsys.readouterr().err
    assert main(["cosim", str(tmp_path), "--out", str(tmp_path / "r")]) == 2
    assert "no OspSystemStructure.xml" in capsys.readouterr().err
