"""Scripted scenarios: every scenario file under scenarios/ runs in closed loop and meets its
pass criteria (the full Pohang canal too, about 30 s). Files with `default_test = false` are
marked slow. Each file is
loaded inside its own test, so a broken file fails that test and no other; `canalnav run`'s
exit status and file list are checked on a tiny scenario."""

import tomllib
from pathlib import Path

import pytest

from bridge.main import main
from scenarios.loop.runner import check_criteria, run_scenario
from scenarios.scenario_file import load_scenario

FILES = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.toml"))


def _default_test(path: Path) -> bool:
    """`scenario.default_test` read without checking the file (that is the test's job)."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))["scenario"]["default_test"] is not False
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, KeyError, TypeError):
        return True


def _param(path):
    marks = [] if _default_test(path) else [pytest.mark.slow]
    return pytest.param(path, id=path.stem, marks=marks)


def test_there_are_scenarios():
    assert {"pohang", "paper_sim", "straight", "sbend", "narrow", "moored_boats",
            "cross_current", "plant_mismatch"} <= {f.stem for f in FILES}


def test_a_broken_file_is_not_skipped_by_the_slow_mark(tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text("[scenario\n")
    assert _default_test(broken)  # so the scenario test runs, and fails on load
    slow = tmp_path / "slow.toml"
    slow.write_text("[scenario]\ndefault_test = false\n")
    assert not _default_test(slow)


@pytest.mark.parametrize("path", [_param(f) for f in FILES])
def test_scenario_meets_its_criteria(path, tmp_path):
    scenario = load_scenario(path)
    result = run_scenario(scenario, tmp_path, plots=False)
    failed = check_criteria(scenario, result.summary)
    assert not failed, f"{path.name}: " + "; ".join(failed) + f"\n{result.summary}"


# -- canalnav run: seed, exit status, the files it lists -----------------------------------------
TINY = """
[scenario]
duration_s = 1.0
seed = 1
goal_radius_m = {goal}

[canal]
centre_line = [[0, 0], [60, 0]]
width_m = 20

[route]
waypoints = [[0, 0], [8, 0]]

[sensors]
perception = "known-walls"

{criteria}
"""


def _run(tmp_path, capsys, goal, criteria=""):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY.format(goal=goal, criteria=criteria))
    out = tmp_path / "out"
    status = main(["run", str(path), "--controller", "los-pid-waypoints", "--plant",
                   "python-model", "--no-plots", "--out", str(out)])
    return status, capsys.readouterr().out, out


def test_run_exits_0_only_when_the_goal_is_reached_and_every_criterion_holds(tmp_path, capsys):
    status, text, _ = _run(tmp_path, capsys, goal=10.0)  # the start is within the goal radius
    assert status == 0 and "criterion failed" not in text
    status, text, _ = _run(tmp_path, capsys, goal=10.0, criteria="[criteria]\nmin_clearance_m = 50")
    assert status == 1 and "criterion failed: min clearance" in text
    status, text, _ = _run(tmp_path, capsys, goal=1.0)  # 1 s is too short to get there
    assert status == 1 and "criterion failed: did not reach the goal" in text


def test_run_without_plots_lists_only_the_files_it_wrote(tmp_path, capsys):
    """run.mcap only with --mcap (issue 35: written by default, 45 MB for straight.toml's
    130 s, and three of them for `compare`), on every install alike."""
    _, text, out = _run(tmp_path, capsys, goal=10.0)
    listed = text.strip().splitlines()[-1]
    assert listed == (f"results in {out}/: summary.json, timing.json, log.csv, segments.csv, "
                      "snapshots.json")
    assert not (out / "run.mcap").exists()
    assert all((out / name).exists() for name in listed.split(": ", 1)[1].split(", "))
    assert not list(out.glob("*.png"))


@pytest.mark.parametrize("seed", ["-3", "1.5", "x"])
def test_run_rejects_a_seed_that_is_not_a_whole_number_from_0(tmp_path, capsys, seed):
    with pytest.raises(SystemExit) as exc:
        main(["run", str(tmp_path / "tiny.toml"), "--seed", seed])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --seed" in err and seed in err and "Traceback" not in err
