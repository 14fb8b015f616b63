"""Studies (`canalnav sweep`): the study file and its errors, the run as a pure function, the
engine on Dask (results as runs end, a run that raises, --resume after an interruption, a
worker killed in the middle), and the report."""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import time
from pathlib import Path

import pytest

from bridge.main import main
from controller.errors import InputError
from scenarios.studies import sweep
from scenarios.studies.overrides import apply_overrides, parse_assignment, parse_path
from scenarios.studies.sweep_spec import load_study, parse_study

# A short straight canal with known walls: a run is a second or two.
TINY = """
[scenario]
name = "tiny"
duration_s = 12
seed = 3

[canal]
centre_line = [[0, 0], [36, 0]]
width_m = 16

[route]
spacing_m = 12

[sensors]
perception = "known-walls"

[controller]
d_p_m = 2.0
"""


@pytest.fixture
def tiny(tmp_path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def study_file(folder: Path, body: str, name: str = "study.toml") -> Path:
    path = folder / name
    path.write_text(body)
    return path


GRID = """
[study]
scenarios = ["tiny.toml"]
seeds = { first = 0, count = 3 }

[overrides]
current.east_mps = [0.0, 0.2]
controller.d_p_m = [2, 3]
"""


# -- the study file ----------------------------------------------------------------------
def test_the_grid_is_every_combination_and_ids_are_stable(tiny, tmp_path):
    study = load_study(study_file(tmp_path, GRID))
    assert len(study.runs) == 12 == study.grid_size
    assert study.factors == ("current.east_mps", "controller.d_p_m")
    combos = {(dict(r.overrides)["current.east_mps"], dict(r.overrides)["controller.d_p_m"],
               r.seed) for r in study.runs}
    assert len(combos) == 12 and {r.controller for r in study.runs} == {"nmpc"}
    again = load_study(tmp_path / "study.toml")
    assert [r.run_id for r in again.runs] == [r.run_id for r in study.runs]
    changed = parse_study(GRID.replace("0.2]", "0.25]"), tmp_path / "study.toml")
    assert len({r.run_id for r in changed.runs} & {r.run_id for r in study.runs}) == 6


def test_a_sample_is_seeded_and_part_of_the_grid(tiny, tmp_path):
    body = GRID.replace("[study]", "[study]\nsample = 5\nsample_seed = 7")
    a = load_study(study_file(tmp_path, body))
    b = load_study(tmp_path / "study.toml")
    full = {r.run_id for r in parse_study(GRID, tmp_path / "study.toml").runs}
    assert len(a.runs) == 5 and [r.run_id for r in a.runs] == [r.run_id for r in b.runs]
    assert {r.run_id for r in a.runs} <= full
    other = parse_study(body.replace("sample_seed = 7", "sample_seed = 8"), tmp_path / "s.toml")
    assert [r.run_id for r in other.runs] != [r.run_id for r in a.runs]


def test_parameter_files_travel_with_the_run(tmp_path):
    (tmp_path / "boat.toml").write_text("[boat]\nNr = -2500.0\n")
    (tmp_path / "tiny.toml").write_text(TINY + "\n[plant.boat]\nfile = \"boat.toml\"\n")
    study = load_study(study_file(tmp_path, '[study]\nscenarios = ["tiny.toml"]\n'))
    (run,) = study.runs
    assert run.files == (("boat.toml", "[boat]\nNr = -2500.0\n"),)
    from scenarios.studies.overrides import scenario_with_overrides

    os.remove(tmp_path / "boat.toml")  # a worker elsewhere has only what travelled
    scenario = scenario_with_overrides(run.scenario_text, run.scenario_file, (), dict(run.files))
    assert scenario.plant_params.Nr == -2500.0


def test_overrides_reach_arrays_of_tables_and_create_tables():
    doc = {"obstacle": [{"z_top_m": 1.0}, {"z_top_m": 2.0}], "scenario": {"duration_s": 10}}
    out = apply_overrides(doc, [("obstacle[1].z_top_m", 3.0), ("plant.boat.Nr", -1.0)])
    assert out["obstacle"][1]["z_top_m"] == 3.0 and out["plant"] == {"boat": {"Nr": -1.0}}
    assert doc["obstacle"][1]["z_top_m"] == 2.0 and "plant" not in doc  # a copy
    assert parse_path("obstacle[1].z_top_m") == ("obstacle", 1, "z_top_m")
    with pytest.raises(ValueError, match="2 of these"):
        apply_overrides(doc, [("obstacle[2].z_top_m", 1.0)])
    with pytest.raises(ValueError, match="is a value"):
        apply_overrides(doc, [("scenario.duration_s.x", 1.0)])
    assert parse_assignment("current.east_mps=0.2") == ("current.east_mps", 0.2)
    assert parse_assignment("controller.type=los-pid") == ("controller.type", "los-pid")
    assert parse_assignment("controller.options.q_diag=[1, 2]")[1] == [1, 2]


# -- bad input: one clear error naming the file and the field, before any run -------------
@pytest.mark.parametrize("overrides, field, says", [
    ("current.eest_mps = [0.1]", "overrides.current.eest_mps", "names no scenario key"),
    ("plant.boat.Nrx = [1.0]", "overrides.plant.boat.Nrx", "names no scenario key"),
    ("controller.d_p_m = ['wide']", "overrides.controller.d_p_m", "expected a number"),
    ("canal.width_m = [16, -3]", "overrides.canal.width_m", "must be > 0"),
    ("current.east_mps = []", "overrides.current.east_mps", "empty list"),
    ("current.east_mps = 0.2", "overrides.current.east_mps", "a single value is [0.2]"),
])
def test_a_bad_override_names_the_study_file_and_field(tiny, tmp_path, overrides, field, says):
    spec = study_file(tmp_path, f'[study]\nscenarios = ["tiny.toml"]\n\n[overrides]\n{overrides}\n')
    with pytest.raises(InputError) as err:
        load_study(spec)
    assert str(spec) in str(err.value) and repr(field)[1:-1] in str(err.value)
    assert says in str(err.value)


@pytest.mark.parametrize("study, field, says", [
    ('scenarios = ["nothere*.toml"]', "study.scenarios", "matches no scenario file"),
    ('scenarios = []', "study.scenarios", "is empty"),
    ('scenarios = ["tiny.toml"]\nseeds = []', "study.seeds", "is empty"),
    ('scenarios = ["tiny.toml"]\nseeds = { first = 0, count = 0 }', "study.seeds.count", "is 0"),
    ('scenarios = ["tiny.toml"]\nseeds = [1, -2]', "study.seeds", ">= 0"),
    ('scenarios = ["tiny.toml"]\ncontrollers = ["mpc"]', "study.controllers", "not a controller"),
    ('scenarios = ["tiny.toml"]\nsample = 2', "study.sample", "grid of 1"),
    ('scenarios = ["tiny.toml"]\nsaple = 2', "study.saple", "unknown field"),
])
def test_a_bad_study_table_names_the_field(tiny, tmp_path, study, field, says):
    spec = study_file(tmp_path, f"[study]\n{study}\n")
    with pytest.raises(InputError) as err:
        load_study(spec)
    assert str(spec) in str(err.value) and field in str(err.value) and says in str(err.value)


def test_the_cli_reports_bad_input_in_one_line_before_any_run(tiny, tmp_path, capsys):
    spec = study_file(tmp_path, '[study]\nscenarios = ["tiny.toml"]\n[overrides]\n'
                      'current.eest_mps = [0.1]\n')
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "overrides.current.eest_mps" in err
    assert not (tmp_path / "out").exists()


def test_an_unreachable_scheduler_is_named(tiny, tmp_path, capsys):
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    spec = study_file(tmp_path, '[study]\nscenarios = ["tiny.toml"]\n')
    address = f"tcp://127.0.0.1:{port}"
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out"), "--scheduler", address,
                 "--connect-timeout", "1"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"--scheduler {address}: cannot reach" in err
    assert not (tmp_path / "out" / "results.csv").exists() or \
        len((tmp_path / "out" / "results.csv").read_text().splitlines()) == 1


def test_run_set_names_a_bad_path(tiny, capsys):
    assert main(["run", str(tiny), "--set", "current.eest_mps=0.2"]) == 2
    err = capsys.readouterr().err
    assert "--set current.eest_mps: names no scenario key" in err and "Traceback" not in err


# -- the run -------------------------------------------------------------------------------
def test_a_run_is_the_same_run_as_canalnav_run_with_set(tiny, tmp_path):
    study = load_study(study_file(tmp_path, '[study]\nscenarios = ["tiny.toml"]\nseeds = [4]\n'
                                  '[overrides]\ncurrent.east_mps = [0.2]\n'))
    (spec,) = study.runs
    out = sweep.execute_run(spec)
    assert out["row"]["status"] == "ok" and out["row"]["seed"] == 4
    assert main(["run", str(tiny), "--seed", "4", "--set", "current.east_mps=0.2", "--no-plots",
                 "--out", str(tmp_path / "direct")]) in (0, 1)
    direct = json.loads((tmp_path / "direct" / "summary.json").read_text())
    # the same run: every result the same; `canalnav run` also records how it was asked for
    assert direct.pop("invocation")["overrides"] == ["current.east_mps=0.2"]
    assert json.loads(out["files"]["summary.json"]) == direct
    assert out["files"]["log.csv"].count(b"\n") > 100


def test_a_run_that_raises_is_recorded_with_its_traceback(tiny, tmp_path, monkeypatch):
    import scenarios.loop.runner as runner

    def broken(*a, **k):
        raise ZeroDivisionError("a bug in the loop")

    monkeypatch.setattr(runner, "run_scenario", broken)
    (spec,) = load_study(study_file(tmp_path, '[study]\nscenarios = ["tiny.toml"]\n')).runs
    out = sweep.execute_run(spec)
    row = out["row"]
    assert row["status"] == "error" and row["outcome"] == "raised ZeroDivisionError"
    assert "a bug in the loop" in row["error"] and "ZeroDivisionError" in out["traceback"]
    assert not row["success"] and not row["soak_passed"]


# -- the engine ----------------------------------------------------------------------------
@pytest.fixture
def threads_client():
    """An in-process Dask cluster of one worker thread (fast to start; processes below)."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(processes=False, n_workers=1, threads_per_worker=1,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        yield client


def _csv(path: Path) -> list[dict]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_a_study_writes_rows_as_runs_end_and_the_report(tiny, tmp_path, threads_client,
                                                        monkeypatch):
    import scenarios.loop.runner as runner

    real = runner.run_scenario

    def sometimes_broken(scenario, out_dir, seed=None, **kw):
        if seed == 1 and scenario.current_ne[1] > 0:
            raise RuntimeError("seed 1 breaks")
        return real(scenario, out_dir, seed=seed, **kw)

    monkeypatch.setattr(runner, "run_scenario", sometimes_broken)
    body = GRID.replace("count = 3", "count = 2").replace("controller.d_p_m = [2, 3]\n", "")
    study = load_study(study_file(tmp_path, body))
    out = tmp_path / "out"
    seen = []

    def on_row(row, client):  # the table grows as runs end
        seen.append(len(_csv(out / "results.csv")))

    outcome = sweep.run_study(study, out, client=threads_client, progress=False, on_row=on_row)
    assert seen == [1, 2, 3, 4]
    rows = _csv(out / "results.csv")
    assert sorted(r["run_id"] for r in rows) == sorted(r.run_id for r in study.runs)
    broken = [r for r in rows if r["status"] == "error"]
    assert len(broken) == 1 and "seed 1 breaks" in broken[0]["error"]
    js = json.loads((out / "results.json").read_text())
    assert len(js) == 4 and "seed 1 breaks" in next(r["traceback"] for r in js
                                                    if r["status"] == "error")
    for r in rows:
        if r["status"] == "ok":
            folder = out / r["folder"]
            assert {"summary.json", "timing.json", "log.csv", "row.json"} <= \
                {p.name for p in folder.iterdir()}
            assert "trajectory.png" not in {p.name for p in folder.iterdir()}  # plots off
    report = (out / "report.md").read_text()
    assert "## By current.east_mps" in report and "## Runs that raised" in report
    assert "canalnav run" in report and "--set current.east_mps=0.2" in report
    assert (out / "factor-current.east_mps.png").stat().st_size > 1000
    assert len(outcome.executed) == 4 and outcome.skipped == 0


def test_resume_after_an_interruption_reruns_nothing_that_finished(tiny, tmp_path,
                                                                  threads_client):
    study = load_study(study_file(tmp_path, GRID.replace("count = 3", "count = 1")))
    out = tmp_path / "out"

    def interrupt(row, client):
        if len(_csv(out / "results.csv")) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        sweep.run_study(study, out, client=threads_client, progress=False, on_row=interrupt)
    first = {r["run_id"]: r for r in _csv(out / "results.csv")}
    assert len(first) == 2
    stamps = {rid: (out / r["folder"] / "summary.json").stat().st_mtime_ns
              for rid, r in first.items()}
    assert "2 not run yet" in (out / "report.md").read_text()
    with pytest.raises(InputError, match="--resume"):
        sweep.run_study(study, out, client=threads_client, progress=False)
    outcome = sweep.run_study(study, out, client=threads_client, progress=False, resume=True)
    assert outcome.skipped == 2 and set(outcome.executed).isdisjoint(first)
    assert len(outcome.executed) == 2
    rows = _csv(out / "results.csv")
    assert sorted(r["run_id"] for r in rows) == sorted(r.run_id for r in study.runs)
    for rid, r in first.items():  # the finished runs were not touched
        assert (out / r["folder"] / "summary.json").stat().st_mtime_ns == stamps[rid]
    again = sweep.run_study(study, out, client=threads_client, progress=False, resume=True)
    assert again.executed == [] and len(again.rows) == 4
    sessions = [json.loads(s) for s in (out / "sessions.jsonl").read_text().splitlines()]
    assert [(s["runs"], s["interrupted"]) for s in sessions] == [(2, True), (2, False)]
    assert "## Sessions" in (out / "report.md").read_text()


@pytest.mark.slow
def test_a_worker_killed_in_the_middle_has_its_runs_run_elsewhere(tiny, tmp_path):
    """A local cluster of two processes; when the first run ends, the worker that ran it
    (now busy with the next) is killed: each run still ends in the table exactly once."""
    distributed = pytest.importorskip("distributed")
    study = load_study(study_file(tmp_path, GRID.replace("count = 3", "count = 2")))
    out = tmp_path / "out"
    killed = {}

    def kill(row, client):
        if killed:
            return
        victim = row["worker"]
        for _ in range(40):  # the scheduler hands it the next run as it hears of this one
            lost = client.processing(workers=[victim]).get(victim, [])
            if lost:
                break
            time.sleep(0.05)
        pid = client.run(os.getpid, workers=[victim])[victim]
        os.kill(pid, signal.SIGKILL)
        killed.update(address=victim, lost=[k.removeprefix("canalnav-run-") for k in lost])

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        outcome = sweep.run_study(study, out, client=client, progress=False, on_row=kill)
    rows = _csv(out / "results.csv")
    ids = [r["run_id"] for r in rows]
    assert sorted(ids) == sorted(r.run_id for r in study.runs)  # each exactly once
    assert all(r["status"] == "ok" for r in rows), [r["error"] for r in rows]
    assert killed["lost"], "the killed worker was running nothing"
    by_id = {r["run_id"]: r for r in rows}
    for rid in killed["lost"]:  # run again, on another worker
        assert by_id[rid]["worker"] != killed["address"]
    assert len(outcome.executed) == len(study.runs)


def test_without_dask_the_error_names_the_extra(tiny, tmp_path, monkeypatch, capsys):
    import builtins

    real = builtins.__import__

    def no_dask(name, *a, **k):
        if name.split(".")[0] in ("distributed", "dask"):
            raise ImportError(f"No module named {name!r}")
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_dask)
    spec = study_file(tmp_path, '[study]\nscenarios = ["tiny.toml"]\n')
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out")]) == 2
    assert "pip install 'canalnav[sweep]'" in capsys.readouterr().err
    assert main(["sweep", str(spec), "--out", str(tmp_path / "o"), "--workers", "2",
                 "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "--workers sizes the local cluster" in capsys.readouterr().err


# -- report.md and the progress line: issue 35's papercuts ----------------------------------
def _fake_outcome(study, make_row):
    from types import SimpleNamespace

    rows = [make_row(i, r) for i, r in enumerate(study.runs)]
    return SimpleNamespace(rows=rows, executed=[r["run_id"] for r in rows], skipped=0,
                           where="a test", wall_s=60.0)


def test_the_report_sorts_values_lists_the_closest_runs_and_runs_from_anywhere(
        tiny, tmp_path, monkeypatch):
    """Issue 35: factor values unsorted (0.2 before 0.0), "Least clearance" listing 10 of 12
    runs, reproduce commands naming a scenario path that held only from the study's folder."""
    from scenarios.studies.sweep_report import write_report

    body = GRID.replace("current.east_mps = [0.0, 0.2]", "current.east_mps = [0.2, 0.0, 0.1]")
    study = load_study(study_file(tmp_path, body.replace("count = 3", "count = 2")))
    assert len(study.runs) == 12

    def row(i, spec):
        return dict({p: v for p, v in spec.overrides}, run_id=spec.run_id,
                    scenario=spec.scenario, seed=spec.seed, controller=spec.controller,
                    status="ok", success=True, soak_passed=True, collision=False,
                    controller_failed=False, min_clearance_m=5.0 + i, control_effort_Jc=100.0,
                    time_below_desired_s=0.0, outcome="reached goal",
                    scenario_file=spec.scenario_file)

    out = tmp_path / "out"
    out.mkdir()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(tmp_path)  # the study's folder: its scenario path is "tiny.toml" here
    report = write_report(study, _fake_outcome(study, row), out).read_text()
    by_current = report.split("## By current.east_mps")[1].split("##")[0]
    values = [line.split("|")[1].strip() for line in by_current.splitlines()
              if line.startswith("| 0.")]
    assert values == ["0.0", "0.1", "0.2"], values
    least = report.split("## Least clearance")[1]
    listed = [line for line in least.splitlines() if line.startswith("- `")]
    assert len(listed) == 3 and "The 3 of 12 finished runs" in least
    command = least.split("  `canalnav run ")[1].split("`")[0]
    monkeypatch.chdir(elsewhere)  # the command, run from another folder, finds the file
    assert Path(command.split()[0]).is_file(), command


def test_after_resume_the_progress_line_counts_the_kept_failures(tiny, tmp_path,
                                                                 threads_client):
    """Issue 35: after --resume the failing count restarted at 0."""
    import io

    body = GRID.replace("count = 3", "count = 1").replace("controller.d_p_m = [2, 3]\n", "")
    body = body.replace("[overrides]\n", "[overrides]\nscenario.duration_s = [2]\n")
    study = load_study(study_file(tmp_path, body))  # 2 runs of 2 s: neither reaches the goal
    out = tmp_path / "out"

    def interrupt(row, client):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        sweep.run_study(study, out, client=threads_client, progress=False, on_row=interrupt)
    stream = io.StringIO()
    sweep.run_study(study, out, client=threads_client, resume=True, stream=stream)
    assert "2/2 runs, 2 failing (0 raised)" in stream.getvalue(), stream.getvalue()
