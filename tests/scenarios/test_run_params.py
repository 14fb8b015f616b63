"""`canalnav run --params TOML`: the controller's model from a parameter file, the plant
keeping the scenario's boat (the closed-loop test of an identified model)."""

import pytest

from controller.errors import InputError
from controller.params import IDENTIFIED
from scenarios.commands.run import load_with_overrides, params_override

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def test_the_controller_gets_the_file_and_the_plant_keeps_its_boat(tmp_path, monkeypatch):
    identified = IDENTIFIED.replace(m22=0.8 * IDENTIFIED.m22, Nr=0.7 * IDENTIFIED.Nr)
    identified.save_toml(tmp_path / "identified.toml", header="test")
    monkeypatch.chdir(tmp_path)  # a path from where the command runs, not the scenario's
    scenario = load_with_overrides(str(ROOT / "scenarios" / "straight.toml"),
                                   [params_override("identified.toml")])
    assert scenario.controller_params.m22 == pytest.approx(0.8 * IDENTIFIED.m22)
    assert scenario.controller_params.Nr == pytest.approx(0.7 * IDENTIFIED.Nr)
    assert scenario.plant_params.m22 == pytest.approx(IDENTIFIED.m22)


def test_a_missing_parameter_file_is_named():
    with pytest.raises(InputError, match="--params nowhere.toml: no such parameter file"):
        params_override("nowhere.toml")
