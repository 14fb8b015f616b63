"""Studies on dask.distributed: many closed-loop runs, results written as each one ends.

A run is a pure function of plain data (`execute_run` of a `RunSpec`: the scenario file's
text, its parameter files' texts, the overrides, the seed, the controller) returning its
row of the results table and the files of its folder, so any Dask worker with the package
installed can do it and no state lives on the workers. The client submits every run,
gathers them as they complete (`as_completed`), writes each run's folder, appends its row to
`results.csv` (flushed) and rewrites `results.json` (atomically); `report.md` and the plots
come at the end (`sweep_report`).

What can go wrong, and what happens:
- a run raises: its row says so, with the error and the traceback; the study goes on;
- a worker dies: Dask runs its runs again on another worker (a run that kills workers
  again and again is recorded as an error, `KilledWorker`);
- the study is interrupted: every finished run is in the table; `--resume` skips them
  (runs that raised are tried again) and does the rest.
Local clusters are processes, one per core with one thread each; inside a worker a run
scans and detects in its own process (the cluster already uses every core).
"""

from __future__ import annotations

import csv
import json
import math
import os
import socket
import sys
import tempfile
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path

from controller.errors import CanalnavError, InputError
from scenarios.studies.sweep_spec import RunSpec, Study

EXTRA_HINT = "pip install 'canalnav[sweep]'"

SUMMARY_COLUMNS = (
    "min_clearance_m", "time_below_desired_s", "control_effort_Jc", "mean_cross_track_m",
    "max_cross_track_m", "duration_s", "steps", "fallback_steps", "time_blind_s",
    "missing_scans",
)
"""Figures of a run's summary.json copied into its row."""


def columns(study: Study) -> list[str]:
    """The results table's columns: the run, its factors, its outcome, its figures."""
    return (["run_id", "scenario", "controller", "seed", *study.override_paths, "status",
             "outcome", "success", "soak_passed", "reached_goal", "collision",
             "controller_failed", "criteria_passed"] + list(SUMMARY_COLUMNS)
            + ["wall_s", "real_time_factor", "worker", "scenario_file", "folder",
               "criteria_failed", "error"])


# -- the run, on a worker -----------------------------------------------------------------
def execute_run(spec: RunSpec) -> dict:
    """Run one study run into a temporary folder and return {"row", "files", "traceback"}:
    its row of the results table, the files of its folder (name -> bytes) and, if it raised,
    the traceback. Never raises for what the run does (a study records it)."""
    from scenarios.loop.runner import check_criteria, run_scenario
    from scenarios.studies.overrides import scenario_with_overrides

    t0 = time.perf_counter()
    row = _base_row(spec)
    row["worker"] = _worker_name()
    tb = ""
    with tempfile.TemporaryDirectory(prefix="canalnav-run-") as tmp:
        out = Path(tmp) / spec.folder
        try:
            scenario = scenario_with_overrides(spec.scenario_text, spec.scenario_file,
                                               spec.overrides, dict(spec.files),
                                               path=Path(spec.scenario_file))
            result = run_scenario(scenario, out, controller=spec.controller, seed=spec.seed,
                                  plant=spec.plant, plots=spec.plots, parallel_perception=False,
                                  mcap=False)  # a study gathers figures, not recordings
            row.update(summary_row(result.summary, result.timing,
                                   check_criteria(scenario, result.summary)))
        except Exception as exc:  # a study records what a run raised, whatever it was
            tb = traceback.format_exc()
            row.update(status="error", outcome=f"raised {type(exc).__name__}",
                       error=_one_line(exc))
        files = {p.name: p.read_bytes() for p in sorted(out.glob("*")) if p.is_file()} \
            if out.is_dir() else {}
    row["wall_s"] = round(time.perf_counter() - t0, 3)
    return {"row": row, "files": files, "traceback": tb}


def summary_row(summary: dict, timing: dict, criteria_failed: list[str]) -> dict:
    """The figures of a finished run for its row."""
    status = str(summary["status"])
    controller_failed = status.startswith("controller failed")
    collision = bool(summary["collision"])
    row = {
        "status": "ok", "outcome": status, "reached_goal": bool(summary["reached_goal"]),
        "collision": collision, "controller_failed": controller_failed,
        "criteria_passed": not criteria_failed, "criteria_failed": "; ".join(criteria_failed),
        "soak_passed": not (collision or controller_failed),
        "success": bool(summary["reached_goal"]) and not criteria_failed and not collision,
        "real_time_factor": _round(timing.get("real_time_factor")),
        "segments_cleaned": dict(summary.get("segments_cleaned", {})),
    }
    row.update({k: summary.get(k) for k in SUMMARY_COLUMNS})
    return row


def _base_row(spec: RunSpec) -> dict:
    row = {"run_id": spec.run_id, "scenario": spec.scenario, "controller": spec.controller,
           "seed": spec.seed}
    row.update({p: v for p, v in spec.overrides})
    row.update(status="error", outcome="", success=False, soak_passed=False,
               reached_goal=False, collision=False, controller_failed=False,
               criteria_passed=False, criteria_failed="", error="",
               scenario_file=spec.scenario_file, folder=f"runs/{spec.folder}")
    return row


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return f"{socket.gethostname()}:{os.getpid()}"


def _one_line(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}".strip().replace("\n", " ")
    return text[:500]


def _round(x, digits: int = 3):
    if x is None or not isinstance(x, (int, float)) or not math.isfinite(x):
        return None
    return round(float(x), digits)


# -- the results folder -------------------------------------------------------------------
class ResultsTable:
    """`results.csv` (a row appended and flushed as each run ends) and `results.json`
    (every row, rewritten atomically at most once a second and at the end), with each run's
    folder under `runs/` (its files and `row.json`, written before its row)."""

    def __init__(self, out_dir: Path, study: Study, rows: list[dict]):
        self.out_dir = Path(out_dir)
        self.columns = columns(study)
        self.rows = list(rows)
        self._json_at = 0.0
        path = self.out_dir / "results.csv"
        self._fh = path.open("w", newline="")  # the kept rows first (resume), then new ones
        self._csv = csv.DictWriter(self._fh, self.columns, extrasaction="ignore")
        self._csv.writeheader()
        for r in self.rows:
            self._csv.writerow(_csv_row(r))
        self._fh.flush()
        self.write_json(force=True)

    def add(self, outcome: dict) -> dict:
        row = outcome["row"]
        row["finished_at"] = _utc_now()
        if outcome.get("traceback"):
            row["traceback"] = outcome["traceback"]
        folder = self.out_dir / row["folder"]
        folder.mkdir(parents=True, exist_ok=True)
        for name, data in outcome.get("files", {}).items():
            (folder / name).write_bytes(data)
        (folder / "row.json").write_text(json.dumps(row, indent=2, default=str) + "\n")
        self.rows.append(row)
        self._csv.writerow(_csv_row(row))
        self._fh.flush()
        self.write_json()
        return row

    def write_json(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._json_at < 1.0:
            return
        self._json_at = now
        _atomic_write(self.out_dir / "results.json",
                      json.dumps(self.rows, indent=1, default=str) + "\n")

    def close(self) -> None:
        self.write_json(force=True)
        self._fh.close()


def _utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def _csv_row(row: dict) -> dict:
    return {k: (v if isinstance(v, str) or v is None else json.dumps(v))
            for k, v in row.items()}


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def finished_rows(out_dir: Path, study: Study) -> list[dict]:
    """The rows already in `out_dir` that `--resume` keeps: runs of this study that
    finished (a run that raised is tried again), read from each run's row.json."""
    path = Path(out_dir) / "results.csv"
    if not path.exists():
        return []
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        header = reader.fieldnames or []
        listed = [(r.get("run_id"), r.get("folder")) for r in reader]
    if header and header != columns(study):
        raise InputError(f"{out_dir}: holds the results of a study with other columns "
                         f"(other overrides); --resume continues the same study: use "
                         f"another --out for this one")
    wanted = {r.run_id for r in study.runs}
    foreign = [rid for rid, _ in listed if rid not in wanted]
    if foreign:
        raise InputError(f"{out_dir}: holds {len(foreign)} runs this study does not have "
                         f"(its file changed?); --resume continues the same study: use "
                         f"another --out")
    kept, seen = [], set()
    for rid, folder in listed:
        try:
            row = json.loads((Path(out_dir) / folder / "row.json").read_text())
        except (OSError, ValueError, TypeError):
            continue  # the row's folder is incomplete: run it again
        if row.get("run_id") == rid and row.get("status") == "ok" and rid not in seen:
            kept.append(row)
            seen.add(rid)
    return kept


# -- progress -----------------------------------------------------------------------------
@dataclass
class Progress:
    """A progress line on stderr: runs done of all, failing (raised, or not a success; with
    --resume the kept runs' failures included), the rate and the time left; redrawn in place
    on a terminal, a line per run elsewhere."""

    total: int
    skipped: int = 0
    stream: object = field(default=sys.stderr)
    done: int = 0
    raised: int = 0
    failed: int = 0
    started: float = field(default_factory=time.perf_counter)

    def update(self, row: dict) -> None:
        self.done += 1
        self.raised += row["status"] != "ok"
        self.failed += not row.get("success")
        elapsed = time.perf_counter() - self.started
        rate = self.done / elapsed if elapsed > 0 else 0.0
        left = (self.total - self.skipped - self.done) / rate if rate > 0 else float("inf")
        frac = (self.skipped + self.done) / self.total if self.total else 1.0
        bar = "#" * int(24 * frac)
        text = (f"[{bar:<24}] {self.skipped + self.done}/{self.total} runs, "
                f"{self.failed} failing ({self.raised} raised), {60 * rate:.1f} runs/min, "
                f"{_duration(left)} left")
        tty = getattr(self.stream, "isatty", lambda: False)()
        if tty:
            self.stream.write(f"\r{text}\033[K")
        else:
            mark = "ok" if row.get("success") else ("RAISED" if row["status"] != "ok" else "failed")
            self.stream.write(f"{text}: {row['scenario']} seed {row['seed']} {mark}\n")
        self.stream.flush()

    def close(self) -> None:
        if getattr(self.stream, "isatty", lambda: False)():
            self.stream.write("\n")
            self.stream.flush()


def _duration(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.1f} min"
    return f"{s / 3600:.1f} h"


# -- the engine ---------------------------------------------------------------------------
@dataclass
class StudyOutcome:
    rows: list  # every row of the table (kept ones first)
    executed: list  # run ids run in this session
    skipped: int  # finished runs found in the folder (--resume)
    wall_s: float
    workers: int
    where: str  # "local cluster of N workers" or the scheduler's address
    interrupted: bool = False
    started_at: str = ""

    def session(self) -> dict:
        """This session's line in sessions.jsonl: where, how many runs, how fast."""
        walls = [r["wall_s"] for r in self.rows if r["run_id"] in set(self.executed)
                 and isinstance(r.get("wall_s"), (int, float))]
        return {"started_at": self.started_at, "ended_at": _utc_now(), "where": self.where,
                "workers": self.workers, "runs": len(self.executed),
                "wall_s": round(self.wall_s, 1), "interrupted": self.interrupted,
                "runs_per_min": round(60 * len(self.executed) / self.wall_s, 3)
                if self.wall_s > 0 else None,
                "mean_run_wall_s": round(sum(walls) / len(walls), 2) if walls else None}


class StudyLost(CanalnavError):
    """The cluster went away in the middle of a study (what finished is in the table)."""


def require_dask():
    """dask.distributed, or an InputError naming the extra to install."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise InputError(f"studies run on dask.distributed, which is not installed: "
                         f"{EXTRA_HINT}") from None
    return distributed


def connect(scheduler: str | None = None, workers: int | None = None,
            timeout_s: float = 10.0):
    """(client, cluster or None, where): an existing scheduler at `scheduler`, or a local
    cluster of `workers` processes (default: one per core), one thread each."""
    distributed = require_dask()
    if scheduler:
        try:
            client = distributed.Client(scheduler, timeout=f"{timeout_s}s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there "
                             f"within {timeout_s:g} s ({type(exc).__name__}: {exc})") from None
        _check_workers(client, scheduler)
        return client, None, f"scheduler {scheduler}"
    n = workers or os.cpu_count() or 1
    cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                       dashboard_address=":0")
    where = f"local cluster of {n} worker{'s' if n > 1 else ''}"
    return distributed.Client(cluster), cluster, where


def _check_workers(client, scheduler: str) -> None:
    """Every worker of an existing cluster can import this package, at this version."""
    mine = package_version()
    try:
        theirs = client.run(package_version)
    except Exception as exc:  # the function does not unpickle there: no package
        raise InputError(f"--scheduler {scheduler}: a worker cannot run canalnav "
                         f"({_one_line(exc)}); install the package on every worker") from None
    wrong = {w: v for w, v in theirs.items() if v != mine}
    if wrong:
        w, v = next(iter(wrong.items()))
        raise InputError(f"--scheduler {scheduler}: worker {w} has canalnav {v}, this client "
                         f"{mine}: install the same version on every worker")


def package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("canalnav")
    except PackageNotFoundError:
        return "unknown"


def _worker_count(client) -> int:
    try:
        return len(client.scheduler_info(n_workers=-1)["workers"])
    except TypeError:  # older distributed
        return len(client.scheduler_info()["workers"])


def check_folder(study: Study, out_dir: Path, resume: bool) -> list[dict]:
    """Check the study folder (nothing written yet) and return the rows --resume keeps."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"--out {out_dir}: is a file, not a folder")
    if (out_dir / "results.csv").exists() and not resume:
        raise InputError(f"--out {out_dir}: already holds a study's results: --resume to "
                         "continue it, or choose another folder")
    return finished_rows(out_dir, study) if resume else []


def _start_folder(study: Study, out_dir: Path) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "study.toml").write_text(study.spec_text)
    _atomic_write(out_dir / "study.json", json.dumps(study_description(study), indent=1,
                                                     default=str) + "\n")


def run_study(study: Study, out_dir, *, client=None, scheduler: str | None = None,
              workers: int | None = None, resume: bool = False, progress: bool = True,
              stream=sys.stderr, on_row=None, timeout_s: float = 10.0) -> StudyOutcome:
    """Run every run of `study` not already finished in `out_dir` on Dask (the `client`
    given, the scheduler at `scheduler`, or a local cluster), writing results as they come.
    `on_row(row, client)` is called after each row is written. The report is written at the
    end, also when interrupted. Bad input (the folder, the scheduler) is an InputError
    before anything is written."""
    from scenarios.studies.sweep_report import write_report

    require_dask()
    out_dir = Path(out_dir)
    kept = check_folder(study, out_dir, resume)
    done_ids = {r["run_id"] for r in kept}
    todo = [r for r in study.runs if r.run_id not in done_ids]
    own = client is None and bool(todo)
    cluster, where, n_workers = None, "no runs left to do", 0
    if own:
        client, cluster, where = connect(scheduler, workers, timeout_s)
    elif client is not None:
        where = f"client of {client.scheduler.address}"
    executed: list[str] = []
    t0 = time.perf_counter()
    started = _utc_now()
    interrupted = True
    try:
        _start_folder(study, out_dir)
        table = ResultsTable(out_dir, study, kept)
        # the kept runs count in the line as in the table: failing ones stay failing
        bar = Progress(len(study.runs), len(kept), stream,
                       failed=sum(not r.get("success") for r in kept)) if progress else None
        try:
            if todo:
                n_workers = _worker_count(client)
                if n_workers == 0 and stream is not None:
                    stream.write(f"{where}: no workers yet; the runs wait for them\n")
                try:
                    _gather(client, todo, table, bar, executed, on_row)
                except (OSError, TimeoutError) as exc:  # the scheduler went away
                    raise StudyLost(f"{where}: lost the connection ({type(exc).__name__}: "
                                    f"{exc}); {len(table.rows)} runs are in {out_dir}: "
                                    f"--resume continues") from None
            interrupted = False
        finally:
            wall = time.perf_counter() - t0
            if bar is not None:
                bar.close()
            table.close()
            outcome = StudyOutcome(table.rows, executed, len(kept), wall, n_workers, where,
                                   interrupted, started)
            if executed or interrupted:
                with (out_dir / "sessions.jsonl").open("a") as fh:
                    fh.write(json.dumps(outcome.session()) + "\n")
            write_report(study, outcome, out_dir)
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    return outcome


def _gather(client, todo: list[RunSpec], table: ResultsTable, bar, executed, on_row) -> None:
    """Submit every run, longest scenarios first and otherwise in the order of their ids
    (a seeded shuffle: each stretch of the study is a mix of its runs, so the rate and the
    time left are fair from the start), and record each as it completes."""
    from distributed import as_completed

    by_key = {}
    futures = []
    for spec in sorted(todo, key=lambda r: (-r.expected_s, r.run_id)):
        f = client.submit(execute_run, spec, key=f"canalnav-run-{spec.run_id}",
                          priority=int(spec.expected_s), pure=False)
        by_key[f.key] = spec
        futures.append(f)
    pending = as_completed(futures)
    try:
        for future in pending:
            spec = by_key[future.key]
            if future.status == "finished":
                outcome = future.result()
            else:  # the run never returned: it killed its workers, or was cancelled
                exc = future.exception()
                row = _base_row(spec)
                row.update(outcome=f"raised {type(exc).__name__}", error=_one_line(exc),
                           worker="")
                outcome = {"row": row, "files": {},
                           "traceback": "".join(traceback.format_exception(exc))}
            row = table.add(outcome)
            executed.append(spec.run_id)
            future.release()
            if bar is not None:
                bar.update(row)
            if on_row is not None:
                on_row(row, client)
    except BaseException:
        client.cancel([f for f in futures if not f.done()])
        raise


def study_description(study: Study) -> dict:
    """What `study.json` says about a study (its runs without their scenario texts)."""
    return {"name": study.name, "spec": str(study.spec_path), "grid_size": study.grid_size,
            "sample": study.sample, "factors": list(study.factors),
            "runs": [{k: v for k, v in asdict(r).items() if k not in ("scenario_text", "files")}
                     | {"parameter_files": [n for n, _ in r.files]} for r in study.runs]}
