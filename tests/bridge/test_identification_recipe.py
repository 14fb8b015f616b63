"""The identification recipe of controller/README.md ("Identifying a boat from its own log"):
`canalnav autopilot-sim --log` with its EKF's noise and a compass bias, `canalnav maneuvers
--connect` from the water's edge of `scenarios/identification/lake.toml`, `canalnav sysid` on
the autopilot's .BIN with no --window, and the closed loop with the identified model.

The slow test runs the README's own lines (ports and folders moved into the test's); the
default one runs the same session in lock-step on a virtual clock, shortened."""

from __future__ import annotations

import math
import re
import resource
import shlex
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bridge.autopilot_sim.ekf import NoiseSpec
from bridge.autopilot_sim.plant import free_udp_port
from bridge.onboard.loop import EXIT_GOAL, BridgeOptions
from bridge.onboard.maneuvers import ManeuverSession
from controller.identification.maneuvers import QUICK_RUNS
from scenarios.scenario_file import load_scenario

ROOT = Path(__file__).resolve().parents[2]
LAKE = ROOT / "scenarios" / "identification" / "lake.toml"


def recipe_lines() -> list[str]:
    """The sh block of controller/README.md that holds the recipe, one command a line."""
    text = (ROOT / "controller" / "README.md").read_text(encoding="utf-8")
    for block in re.findall(r"```sh\n(.*?)```", text, re.S):
        if "maneuvers -o runs/boat --connect" in block:
            return [line.strip() for line in block.splitlines() if line.strip()]
    raise AssertionError("controller/README.md: no sh block with the identification recipe")


def sysid_table(out: str) -> dict[str, float]:
    """The ratio errors (%) of sysid's table, by parameter."""
    found = {}
    for line in out.splitlines():
        m = re.match(r"(\w+)\s+\S+\s+\S+\s+\S+\s+\S+\s+\S+\s+([+-]\d+\.\d+)%", line)
        if m:
            found[m.group(1)] = float(m.group(2))
    return found


def test_the_recipe_is_one_session_then_sysid_then_the_closed_loop():
    lines = recipe_lines()
    assert [shlex.split(line)[1] for line in lines if line.startswith(".venv")] == [
        "autopilot-sim", "maneuvers", "sysid", "run"]
    assert not any("--window" in line or "--origin" in line for line in lines)
    assert load_scenario(LAKE).geodetic_origin is not None  # so no --origin is needed


@pytest.mark.slow  # about 8 minutes of boat time at --speedup 2, then sysid and Pohang
def test_the_readme_recipe_runs_as_written(tmp_path):
    exe = str(Path(sys.executable).with_name("canalnav"))
    port = str(free_udp_port())

    def command(line: str) -> list[str]:
        words = shlex.split(line.rstrip("&").strip())
        out = []
        for w in words:
            w = w.replace("14550", port)
            if w == ".venv/bin/canalnav":
                w = exe
            elif w.startswith("runs/"):
                w = str(tmp_path / w)
            elif w.startswith("scenarios/"):
                w = str(ROOT / w)
            out.append(w)
        return out

    ap = None
    outputs = {}
    try:
        for line in recipe_lines():
            if line.endswith("&"):
                ap = subprocess.Popen(command(line), cwd=tmp_path, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True)
                continue
            if line.startswith("kill"):
                ap.send_signal(signal.SIGTERM)
                ap.wait(timeout=60)
                continue
            cmd = command(line)
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            done = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True,
                                  timeout=3600)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
            outputs[cmd[1]] = (done, cpu)
            (tmp_path / f"{cmd[1]}.out").write_text(  # to read after a failure
                f"{line}\nCPU {cpu:.1f} s, exit {done.returncode}\n{done.stdout}\n{done.stderr}")
            assert done.returncode == 0, (line, done.stdout[-3000:], done.stderr[-3000:])
    finally:
        if ap is not None and ap.poll() is None:
            ap.kill()
            ap.wait()
    session = outputs["maneuvers"][0].stderr
    assert re.search(r"first \d+ m on heading", session)  # it starts at the water's edge
    assert "cut short" not in session and "gap of" not in session, session[-3000:]
    late = re.search(r"steps late .* the worst by ([\d.]+) s", session)
    assert late is None or float(late.group(1)) < 1.0, late  # within runs only: no gaps
    sysid, cpu = outputs["sysid"]
    assert cpu < 300.0, cpu  # at most 5 minutes of CPU
    text = sysid.stdout
    # the acceleration and the deceleration staircases run on one heading are one surge run
    assert ("acceleration found" in text or "surge found" in text) and "zigzag found" in text
    biases = [float(b) for b in re.findall(r"([+-]\d+\.\d+) deg", text.split(
        "heading bias of each run")[1].splitlines()[0])]
    assert biases and all(abs(b - 2.0) < 1.0 for b in biases), biases
    assert (tmp_path / "runs" / "identified.toml").is_file()
    assert "criterion failed" not in outputs["run"][0].stdout


@pytest.fixture(scope="module")
def edge_session(tmp_path_factory):
    """The recipe's session in lock-step on a virtual clock (the quick runs, levels held
    15 s, a compass 2 deg off), from the canal's end: (result, console, the .BIN)."""
    from tests.bridge.rigs import SimRig

    tmp = tmp_path_factory.mktemp("edge")
    lake = load_scenario(LAKE)
    rig = SimRig(lake, tmp / "work", seed=3, tick_s=0.02, ekf_delay_s=5.0, init_s=2.0,
                 log_dir=tmp / "ap", physics_step_s=0.02,
                 ekf_noise=NoiseSpec(heading_bias_rad=math.radians(2.0)),
                 link_kwargs={"geodetic_origin": lake.geodetic_origin})
    try:
        session = ManeuverSession(rig.link, lake, QUICK_RUNS,
                                  BridgeOptions(mode="MANUAL", arm=True, ekf_timeout_s=30.0),
                                  tmp / "boat", console=rig.console, hold_s=15.0)
        result = session.run()
        xy = np.array(rig.autopilot.true_state[:2])
    finally:
        rig.close()  # the .BIN complete
    (bin_path,) = rig.autopilot.log_paths
    return result, rig.console.getvalue(), bin_path, xy


def test_a_session_from_the_water_edge_goes_to_open_water_first(edge_session):
    """The boat starts at the canal's end: it goes to open water first, no run is cut short,
    no step between runs counts as late, and the runs are found in the autopilot's .BIN."""
    from controller.identification.dataflash import read_dataflash
    from controller.identification.log_runs import find_runs

    result, console, bin_path, xy = edge_session
    assert result.exit_code == EXIT_GOAL, console[-2000:]
    assert "is not in open water" in console and re.search(r"first \d+ m on heading", console), console
    assert not any(r.cut_short for r in result.runs), [r.cut_short for r in result.runs]
    assert result.late_steps == 0 and "steps late" not in console
    assert all(p is not None for p in result.paths)
    assert 0.0 < xy[0] < 2000.0 and abs(xy[1]) < 300.0  # stayed on the lake
    kinds = [r.meta["maneuver"] for r in find_runs(read_dataflash(bin_path))]
    assert kinds.count("zigzag") == 2 and "acceleration" in kinds, kinds


@pytest.mark.slow  # about 70 s of identification
def test_sysid_finds_the_runs_in_the_sessions_bin_and_identifies(edge_session, capsys):
    from bridge.main import main

    bin_path = edge_session[2]
    capsys.readouterr()
    assert main(["sysid", str(bin_path)]) == 0
    out = capsys.readouterr().out
    assert out.count("zigzag found") == 2 and "acceleration found" in out
    assert "sway-yaw stage" in out and "heading bias of each run" in out
