"""The study file of `canalnav sweep` (TOML): which runs a study makes, checked before any runs.

    [study]
    name = "current-and-separation"          # default: the file's name
    scenarios = ["../scenarios/straight.toml", "../scenarios/n*.toml"]  # paths or globs,
                                              # relative to this file
    seeds = { first = 0, count = 20 }         # or a list [1, 2, 3]; default: each file's seed
    controllers = ["nmpc", "los-pid"]         # default: each scenario's own
    sample = 200                              # a seeded random sample of the grid (default: all)
    sample_seed = 0
    plots = false                             # each run's PNG plots
    plant = "fmu"                             # or "python-model"

    [overrides]                               # any scenario key by its dotted path
    current.east_mps = [0.0, 0.1, 0.2, 0.3, 0.4]
    controller.d_p_m = [2.0, 4.0]
    "obstacle[0].remove_at_s" = [60, 120]     # (a quoted key for an index)

The runs are the grid of scenarios x controllers x override values x seeds, or a sample of
it. Every run is plain data (`RunSpec`): the scenario file's text and its parameter files'
texts travel with it, so a worker needs only the package. Every value is checked against its
scenario here, so a bad path or value stops the study before any run, naming the study
file, the field and the scenario's own complaint.
"""

from __future__ import annotations

import glob
import hashlib
import itertools
import os
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from controller.errors import InputError
from scenarios.scenario_file import _Table, parameter_file_path, parse_toml
from scenarios.studies.overrides import apply_overrides, parse_path, scenario_with_overrides

MAX_COMBINATIONS_CHECKED = 256
"""Per scenario file, every combination of override values is parsed before the study when
there are at most this many; beyond, each value is checked on its own (and a combination
that does not fit is recorded by its run)."""


@dataclass(frozen=True)
class RunSpec:
    """One run of a study, as plain data: what `execute_run` needs on any worker."""

    run_id: str
    scenario: str  # the scenario's name
    scenario_file: str  # the file as found (for messages and the command that reproduces it)
    scenario_text: str
    files: tuple  # ((name as the scenario gives it, text), ...) of its parameter files
    overrides: tuple  # ((dotted path, value), ...)
    seed: int
    controller: str
    plant: str = "fmu"
    plots: bool = False
    expected_s: float = 0.0  # the scenario's duration (longest runs go first)

    @property
    def folder(self) -> str:
        return f"{self.scenario}-{self.run_id}"


@dataclass(frozen=True)
class Study:
    name: str
    spec_path: Path
    spec_text: str
    runs: tuple  # RunSpec, in grid order
    override_paths: tuple  # dotted paths, in the file's order
    factors: tuple  # what varies: "scenario", "controller" and the override paths
    grid_size: int
    sample: int | None = None


def run_id(scenario_text: str, files, overrides, seed: int, controller: str, plant: str) -> str:
    """A stable id of what a run computes (16 hex digits of a SHA-256): the same inputs give
    the same id in any session, so `--resume` recognises a finished run."""
    blob = json.dumps({"scenario": scenario_text, "files": [list(f) for f in files],
                       "overrides": [[p, v] for p, v in overrides], "seed": seed,
                       "controller": controller, "plant": plant}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def load_study(path: str | Path) -> Study:
    """Read and check a study file: every scenario found, every override placed and every
    value accepted by its scenario, or an InputError naming the file and the field."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: no such study file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, not a study file (give a .toml file)") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not UTF-8 text; a study is a TOML file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the study file: {exc.strerror}") from None
    return parse_study(text, path)


def parse_study(text: str, path: Path) -> Study:
    source = str(path)
    doc = _Table(parse_toml(text, source), "", source)
    meta = doc.table("study", required=True)
    name = meta.string("name", path.stem)
    meta.string("description", "")
    scenario_files = _scenario_files(meta, path.parent)
    seeds = _seeds(meta)
    controllers = _controllers(meta)
    sample = meta.integer("sample", None, low=1)
    sample_seed = meta.integer("sample_seed", 0, low=0)
    plots = meta.boolean("plots", False)
    plant = meta.string("plant", "fmu", choices=("fmu", "python-model"))
    meta.done()
    overrides = _overrides(doc.table("overrides"), source)
    doc.done()

    paths = tuple(p for p, _ in overrides)
    combos = list(itertools.product(*[[(p, v) for v in values] for p, values in overrides]))
    runs = []
    for file in scenario_files:
        scenario_text = _read_scenario(file, source)
        base = _check_overrides(scenario_text, str(file), overrides, combos, source)
        for combo in combos:
            files = _parameter_files(scenario_text, str(file), combo, source)
            for controller in controllers or (base.controller,):
                for seed in (seeds if seeds is not None else (base.seed,)):
                    rid = run_id(scenario_text, files, combo, seed, controller, plant)
                    runs.append(RunSpec(rid, base.name, str(file), scenario_text, files, combo,
                                        int(seed), controller, plant, plots,
                                        float(base.duration_s)))
    grid = len(runs)
    if sample is not None:
        if sample > grid:
            raise InputError(f"{source}: field 'study.sample': {sample} runs asked of a grid "
                             f"of {grid}")
        keep = np.sort(np.random.default_rng(sample_seed).choice(grid, sample, replace=False))
        runs = [runs[i] for i in keep]
    ids = [r.run_id for r in runs]
    if len(set(ids)) != len(ids):  # the same file twice under two names, say
        seen, dup = set(), None
        for r in runs:
            if r.run_id in seen:
                dup = r
                break
            seen.add(r.run_id)
        raise InputError(f"{source}: two runs of the grid are the same run ({dup.scenario_file}, "
                         f"seed {dup.seed}, {dict(dup.overrides)}): is a scenario named twice?")
    factors = []
    if len(scenario_files) > 1:
        factors.append("scenario")
    if len({r.controller for r in runs}) > 1:
        factors.append("controller")
    factors += [p for p, values in overrides if len(values) > 1]
    return Study(name, path, text, tuple(runs), paths, tuple(factors), grid, sample)


def _scenario_files(meta: _Table, folder: Path) -> list[Path]:
    if not meta.has("scenarios"):
        raise meta.err("scenarios", "is required (scenario files or globs, relative to the "
                       "study file)")
    patterns = meta.raw("scenarios")
    if isinstance(patterns, str):
        patterns = [patterns]
    if not isinstance(patterns, list) or not all(isinstance(p, str) for p in patterns):
        raise meta.err("scenarios", f"expected a list of paths or globs, got {patterns!r}")
    if not patterns:
        raise meta.err("scenarios", "is empty: a study needs at least one scenario file")
    found: list[Path] = []
    for pattern in patterns:
        full = pattern if Path(pattern).is_absolute() else str(folder / pattern)
        matches = sorted(Path(os.path.normpath(m)) for m in glob.glob(full, recursive=True))
        matches = [m for m in matches if m.is_file()]
        if not matches:
            raise meta.err("scenarios", f"{pattern!r} matches no scenario file (looked in "
                           f"{Path(full).parent})")
        found += [m for m in matches if m.resolve() not in {f.resolve() for f in found}]
    return found


def _seeds(meta: _Table):
    if not meta.has("seeds"):
        return None
    v = meta.raw("seeds")
    if isinstance(v, dict):
        t = _Table(v, "study.seeds", meta.source)
        first = t.integer("first", 0, low=0)
        if not t.has("count"):
            raise t.err("count", "is required (seeds first, first + 1, ..., first + count - 1)")
        count = t.integer("count", low=0)
        t.done()
        if count == 0:
            raise t.err("count", "is 0: the study would have no runs")
        return tuple(range(first, first + count))
    if not isinstance(v, list) or not all(isinstance(s, int) and not isinstance(s, bool)
                                          for s in v):
        raise meta.err("seeds", f"expected a list of whole numbers or {{ first = 0, count = 20 }}, "
                       f"got {v!r}")
    if not v:
        raise meta.err("seeds", "is empty: the study would have no runs")
    if any(s < 0 for s in v):
        raise meta.err("seeds", f"must all be >= 0, got {v!r}")
    if len(set(v)) != len(v):
        raise meta.err("seeds", f"repeats a seed (the same seed gives the same run): {v!r}")
    return tuple(v)


def _controllers(meta: _Table):
    from scenarios.loop.runner import CONTROLLERS

    if not meta.has("controllers"):
        return None
    v = meta.raw("controllers")
    if not isinstance(v, list) or not all(isinstance(c, str) for c in v):
        raise meta.err("controllers", f"expected a list of controller names, got {v!r}")
    if not v:
        raise meta.err("controllers", "is empty: the study would have no runs")
    bad = [c for c in v if c not in CONTROLLERS]
    if bad:
        raise meta.err("controllers", f"{bad[0]!r} is not a controller (choose from: "
                       f"{', '.join(CONTROLLERS)})")
    return tuple(dict.fromkeys(v))


def _overrides(t: _Table | None, source: str) -> list:
    """[overrides] as [(dotted path, [values])], in the file's order; nested tables (TOML's
    dotted keys) are paths, and the leaf is the list of values."""
    if t is None:
        return []
    out = []

    def walk(node, prefix):
        for key, value in node.items():
            path = f"{prefix}.{key}" if prefix else key
            field = f"overrides.{path}"
            if isinstance(value, dict):
                if not value:
                    raise InputError(f"{source}: field {field!r}: an empty table gives no runs")
                walk(value, path)
                continue
            try:
                parse_path(path)
            except ValueError as exc:
                raise InputError(f"{source}: field {field!r}: {exc}") from None
            if not isinstance(value, list):
                raise InputError(f"{source}: field {field!r}: expected a list of values (one "
                                 f"run for each), got {value!r}; a single value is [{value!r}]")
            if not value:
                raise InputError(f"{source}: field {field!r}: an empty list of values gives "
                                 "no runs")
            out.append((path, value))

    walk(t.data, "")
    t.used.update(t.data)
    return out


def _read_scenario(file: Path, source: str) -> str:
    try:
        return file.read_bytes().decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{source}: field 'study.scenarios': cannot read {file}: {exc}") from None


def _check_overrides(text: str, file: str, overrides, combos, source: str):
    """Each value on its own against the scenario, then every combination (up to
    MAX_COMBINATIONS_CHECKED): the scenario as the file has it is returned."""
    def field(p):
        return f"{source}: field 'overrides.{p}' (for {file})"

    files = dict(_parameter_files(text, file, (), source))
    base = scenario_with_overrides(text, file, (), files)
    for p, values in overrides:
        for v in values:
            scenario_with_overrides(text, file, [(p, v)],
                                    dict(_parameter_files(text, file, [(p, v)], source)),
                                    given_at=field)
    if len(overrides) > 1 and len(combos) <= MAX_COMBINATIONS_CHECKED:
        for combo in combos:
            scenario_with_overrides(text, file, combo,
                                    dict(_parameter_files(text, file, combo, source)),
                                    given_at=field)
    return base


def _parameter_files(text: str, file: str, overrides, source: str) -> tuple:
    """The texts of the parameter files the scenario (with these overrides) names in
    [plant.boat] and [controller.boat], to travel with the run."""
    doc = parse_toml(text, file)
    try:
        doc = apply_overrides(doc, overrides)
    except ValueError:
        return ()  # the override check names it
    out = {}
    for table in ("plant", "controller"):
        boat = doc.get(table, {}).get("boat", {}) if isinstance(doc.get(table), dict) else {}
        rel = boat.get("file") if isinstance(boat, dict) else None
        if isinstance(rel, str) and rel not in out:
            p = parameter_file_path(file, rel)
            try:
                out[rel] = p.read_bytes().decode("utf-8")
            except (OSError, UnicodeDecodeError) as exc:
                raise InputError(f"{file}: field '{table}.boat.file': cannot read {p}: "
                                 f"{exc}") from None
    return tuple(sorted(out.items()))
