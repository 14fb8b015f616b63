"""Bad input gets an FMI error with a message naming the variable and value; never NaN outputs."""

from pathlib import Path

import numpy as np
import pytest

from bridge.main import main
from controller.errors import InputError
from fmu.plant import FmuBoat


@pytest.fixture
def boat(fmu_path):
    with FmuBoat(fmu_path) as b:
        b.setup(state0=[0, 0, 0, 1.0, 0, 0])
        b.step(30.0, 0.0, 0.1)
        yield b


def assert_still_healthy(boat, before):
    assert np.array_equal(boat.outputs(), before)
    assert np.isfinite(boat.step(30.0, 0.0, 0.1)).all()


@pytest.mark.parametrize("name,value", [
    ("nT", float("nan")), ("nS", float("inf")), ("current_north", float("nan")),
    ("current_east", -float("inf")),
])
def test_non_finite_inputs_are_refused(boat, name, value):
    before = boat.outputs()
    with pytest.raises(InputError) as err:
        boat.set_values({name: value})
    assert name in str(err.value) and str(value).lower().lstrip("-")[:3] in str(err.value).lower()
    assert_still_healthy(boat, before)


def test_nan_command_through_step_is_refused(boat):
    before = boat.outputs()
    with pytest.raises(InputError, match="nS.*nan"):
        boat.step(10.0, float("nan"), 0.1)
    assert_still_healthy(boat, before)


@pytest.mark.parametrize("name,value", [("m11", 0.0), ("m22", -5.0), ("m33", -1e-9),
                                        ("internal_step", 0.0), ("internal_step", -0.05),
                                        ("delta_max", 0.0), ("dnT_max", -1.0)])
def test_non_positive_masses_step_sizes_and_negative_rates_are_refused(boat, name, value):
    before = boat.outputs()
    with pytest.raises(InputError) as err:
        boat.set_values({name: value})
    assert name in str(err.value) and repr(value).rstrip("0").rstrip(".") in str(err.value)
    assert_still_healthy(boat, before)


def test_non_positive_mass_before_initialization_is_refused(fmu_path):
    with FmuBoat(fmu_path) as b:
        with pytest.raises(InputError, match="m11.*-1914.9"):
            b.set_values({"m11": -1914.9})
        assert b.get_values(["m11"])[0] > 0


@pytest.mark.parametrize("step", [0.0, -0.1, float("nan"), float("inf")])
def test_bad_communication_step_sizes_are_refused(boat, step):
    before = boat.outputs()
    with pytest.raises(InputError, match="step size"):
        boat.step(30.0, 0.0, step)
    assert np.array_equal(boat.outputs(), before)


def test_a_diverging_step_fails_without_nan_outputs(boat):
    """Absurd but finite parameters blow the state up: error, last good outputs kept."""
    boat.set_values({"c": 1e300})
    before = boat.outputs()
    with pytest.raises(InputError, match="non-finite"):
        boat.step(100.0, 0.0, 1.0)
    after = boat.outputs()
    assert np.isfinite(after).all() and np.array_equal(after, before)


def test_unknown_variable_and_type_errors(boat):
    with pytest.raises(InputError, match="unknown variable"):
        boat.set_values({"speed": 1.0})
    with pytest.raises(Exception):
        boat._slave.setReal([999], [1.0]) if boat.fmi_version == 2 else \
            boat._slave.setFloat64([999], [1.0])
    assert "999" in boat.messages[-1]


def test_fmu_boat_refuses_a_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such FMU"):
        FmuBoat(tmp_path / "none.fmu")


def test_bench_rejects_bad_options(capsys):
    assert main(["bench", "fmu", "--dt", "0"]) == 2
    assert main(["bench", "fmu", "--steps", "0"]) == 2
    assert "--dt" in capsys.readouterr().err


def test_check_rejects_a_non_positive_compare_step(fmus, capsys):
    assert main(["fmu", "check", str(fmus[2]), "--compare", "--step", "-1"]) == 2
    assert "--step" in capsys.readouterr().err


def test_check_compare_of_an_fmu_whose_binary_does_not_load(fmus, tmp_path, capsys,
                                                            monkeypatch):
    """A broken binary inside: the check and the comparison each report it on a line, the
    exit status is 1, no traceback; a relative path still works after fmpy's failed load
    (which left the process in a deleted folder)."""
    import zipfile

    bad = tmp_path / "bad.fmu"
    with zipfile.ZipFile(fmus[2]) as src, zipfile.ZipFile(bad, "w") as dst:
        for info in src.infolist():
            data = src.read(info.filename)
            dst.writestr(info, b"garbage" * 10 if info.filename.endswith(".so") else data)
    monkeypatch.chdir(tmp_path)
    assert main(["fmu", "check", "bad.fmu", "--compare", "--step", "1.0"]) == 1
    out = capsys.readouterr().out
    assert "bad.fmu: comparison at step 1 failed" in out and "ELF" in out
    assert Path.cwd() == tmp_path
