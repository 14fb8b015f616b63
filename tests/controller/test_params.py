"""Parameter sets: TOML round trip and clear errors."""

import math

import pytest

from controller.errors import InputError
from controller.params import IDENTIFIED, PARAM_NAMES, BoatParams


def test_toml_round_trip(tmp_path):
    changed = IDENTIFIED.replace(m11=2000.5, Nrr=-190.25, delta_max=math.radians(30))
    path = tmp_path / "p.toml"
    changed.save_toml(path, header="test set")
    back = BoatParams.from_toml(path)
    for name in PARAM_NAMES:
        assert getattr(back, name) == getattr(changed, name)
    text = path.read_text()
    assert "delta_max = 30.0  # deg" in text
    assert "# test set" in text


def test_partial_table_keeps_defaults(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text("[boat]\nm11 = 2500.0\n")
    p = BoatParams.from_toml(path)
    assert p.m11 == 2500.0 and p.Xu == IDENTIFIED.Xu


@pytest.mark.parametrize(
    "body, words",
    [
        ("[boat]\nmass = 3.0\n", ["unknown boat parameter 'mass'"]),
        ("[boat]\nm11 = 'heavy'\n", ["'m11'", "heavy"]),
        ("[boat]\nm11 = -5.0\n", ["'m11'", "positive", "-5.0"]),
        ("[boat]\nm22 = nan\n", ["'m22'", "not finite"]),
        ("[boat\nm11 = 1\n", ["not valid TOML"]),
    ],
)
def test_bad_files_name_the_problem(tmp_path, body, words):
    path = tmp_path / "bad.toml"
    path.write_text(body)
    with pytest.raises(InputError) as err:
        BoatParams.from_toml(path)
    msg = str(err.value)
    assert str(path) in msg
    for w in words:
        assert w in msg


def test_missing_file_is_named(tmp_path):
    with pytest.raises(InputError, match="no such parameter file"):
        BoatParams.from_toml(tmp_path / "nope.toml")
