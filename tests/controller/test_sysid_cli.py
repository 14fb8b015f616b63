"""`canalnav maneuvers`, `canalnav sysid` and `canalnav bench sysid` from the command line."""

import json

import pytest

from bridge.main import main
from controller.params import BoatParams


@pytest.fixture(scope="module")
def log_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("logs")
    assert main(["maneuvers", "-o", str(out), "--seed", "2", "--quick"]) == 0
    return out


def test_maneuvers_writes_every_run(log_dir, capsys):
    names = sorted(p.name for p in log_dir.glob("*.csv"))
    assert names == ["01_acceleration.csv", "02_deceleration.csv", "03_zigzag_20_50.csv",
                     "04_heldout_zigzag_10_30.csv"]
    assert "# use: heldout" in (log_dir / "04_heldout_zigzag_10_30.csv").read_text()


def test_sysid_json_and_toml_from_straight_runs_with_a_heldout(log_dir, tmp_path, capsys):
    out = tmp_path / "p.toml"
    args = ["sysid", str(log_dir / "01_acceleration.csv"), str(log_dir / "02_deceleration.csv"),
            "--heldout", str(log_dir / "03_zigzag_20_50.csv"), "--json", "-o", str(out),
            "--fix", "m22=1800"]
    assert main(args) == 0
    report = json.loads(capsys.readouterr().out)
    assert [s["name"] for s in report["stages"]] == ["surge"]
    assert report["stages"][0]["ipopt_iterations"] > 0
    assert report["heldout"][0]["log"].endswith("03_zigzag_20_50.csv")
    rows = {r["name"]: r for r in report["parameters"]}
    assert abs(rows["c"]["ratio_error"]) < 0.05 and rows["c"]["std_error"] > 0
    assert rows["m22"]["role"] == "fixed"
    params = BoatParams.from_toml(out)
    assert params.m22 == 1800.0 and params.c == pytest.approx(rows["c"]["estimate"])
    assert "Söding" in out.read_text()


@pytest.mark.slow  # (27 s: a whole quick identification; for CI time)
def test_sysid_table_and_bench_json(log_dir, capsys):
    assert main(["bench", "sysid", "--quick", "--seed", "2"]) == 0
    bench = json.loads(capsys.readouterr().out)
    assert set(bench["stages"]) == {"surge", "sway-yaw"}
    for stage in bench["stages"].values():
        assert stage["ipopt_iterations"] > 0 and stage["solve_s"] > 0
    assert bench["generate_logs_s"] > 0 and bench["total_s"] >= bench["identify_total_s"]


def test_missing_column_is_one_line_naming_file_line_and_column(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time [s],u [m/s],nT [%],nS [%]\n0,1,30,0\n0.1,1,30,0\n")
    assert main(["sysid", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"{bad}:1" in err and "'psi'" in err


def test_missing_file_and_bad_fix(tmp_path, capsys):
    assert main(["sysid", str(tmp_path / "nope.csv")]) == 2
    assert "no such log file" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["sysid", "x.csv", "--fix", "m11"])
    assert exc.value.code == 2
    assert "NAME=VALUE" in capsys.readouterr().err
    assert main(["sysid", "x.csv", "--select-se", "0"]) == 2
    err = capsys.readouterr().err
    assert "--select-se" in err and "Traceback" not in err


@pytest.mark.slow
def test_readme_main_job(tmp_path, capsys):
    """The README's pair: the paper's runs, then sysid on every CSV (held-out one included)."""
    logs = tmp_path / "runs" / "logs"
    assert main(["maneuvers", "-o", str(logs), "--seed", "1"]) == 0
    paths = sorted(str(p) for p in logs.glob("*.csv"))
    assert main(["sysid", *paths, "-o", str(tmp_path / "runs" / "params.toml")]) == 0
    text = capsys.readouterr().out
    assert "held-out" in text and "04_heldout_zigzag_10_30.csv (" in text
    BoatParams.from_toml(tmp_path / "runs" / "params.toml")
