"""Scripted scenarios: every scenario file under scenarios/ runs in closed loop and meets its
pass criteria. Files with `default_test = false` (the full canal) are marked slow."""

from pathlib import Path

import pytest

from scenarios.runner import check_criteria, run_scenario
from scenarios.scenario_file import load_scenario

FILES = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.toml"))


def _param(path):
    marks = [] if load_scenario(path).default_test else [pytest.mark.slow]
    return pytest.param(path, id=path.stem, marks=marks)


def test_there_are_scenarios():
    assert {"pohang", "paper_sim", "straight", "sbend", "narrow", "moored_boats",
            "cross_current", "plant_mismatch"} <= {f.stem for f in FILES}


@pytest.mark.parametrize("path", [_param(f) for f in FILES])
def test_scenario_meets_its_criteria(path, tmp_path):
    scenario = load_scenario(path)
    result = run_scenario(scenario, tmp_path, plots=False)
    failed = check_criteria(scenario, result.summary)
    assert not failed, f"{path.name}: " + "; ".join(failed) + f"\n{result.summary}"
