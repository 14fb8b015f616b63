"""A soak of the product: every scenario file with many seeds, and what must never happen.

A soak is a study (`sweep`) over files x seeds with the product's pass rule, not the
scenarios' criteria: no run raises, no hull touches anything, no controller fails. It runs
on the same engine (a local Dask cluster, or a scheduler's workers), writes the same folder
(results table, report, each run's folder) and adds what perception had to clean away.
`scenarios/studies/soak.toml` is the same soak as a study file for `canalnav sweep`.
"""

from __future__ import annotations

from pathlib import Path

from scenarios.studies.overrides import toml_value
from scenarios.studies.sweep_spec import Study, parse_study

SCENARIO_DIR = Path(__file__).resolve().parents[1]
SPEC = Path(__file__).resolve().with_name("soak.toml")


def scenario_files() -> list[Path]:
    """Every scenario file of the package (`scenarios/*.toml`)."""
    return sorted(SCENARIO_DIR.glob("*.toml"))


def soak_study(paths, seeds, plant: str = "fmu") -> Study:
    """The study of every file in `paths` with every seed (all checked as a study file is)."""
    paths = [str(Path(p).resolve()) for p in paths]
    text = (f"# soak: every scenario file x seeds; pass rule: no exception, collision or "
            f"controller failure\n[study]\nname = \"soak\"\n"
            f"scenarios = {toml_value(paths)}\nseeds = {toml_value(list(seeds))}\n"
            f"plant = {toml_value(plant)}\n")
    return parse_study(text, Path.cwd() / "soak.toml")


def passed(row: dict) -> bool:
    """The soak's rule for one run: it did not raise, collide or fail its controller."""
    return row["status"] == "ok" and not row["collision"] and not row["controller_failed"]


def report(rows: list[dict], wall_s: float) -> dict:
    """The soak's figures: runs, failures by kind, what perception cleaned, per scenario."""
    cleaned: dict[str, int] = {}
    for r in rows:
        for k, v in (r.get("segments_cleaned") or {}).items():
            cleaned[k] = cleaned.get(k, 0) + int(v)
    per_scenario: dict[str, dict] = {}
    for r in sorted(rows, key=lambda r: (r["scenario"], r["seed"])):
        p = per_scenario.setdefault(r["scenario"], {"runs": 0, "reached_goal": 0, "failed": 0})
        p["runs"] += 1
        p["reached_goal"] += bool(r["reached_goal"])
        p["failed"] += not passed(r)
    return {
        "runs": len(rows),
        "scenario_files": len(per_scenario),
        "seeds": sorted({r["seed"] for r in rows}),
        "passed": bool(rows) and all(passed(r) for r in rows),
        "exceptions": sum(r["status"] != "ok" for r in rows),
        "collisions": sum(bool(r["collision"]) for r in rows),
        "controller_failures": sum(bool(r["controller_failed"]) for r in rows),
        "reached_goal": sum(bool(r["reached_goal"]) for r in rows),
        "criteria_passed": sum(bool(r.get("criteria_passed")) for r in rows),
        "fallback_steps": sum(int(r.get("fallback_steps") or 0) for r in rows),
        "segments_cleaned": cleaned,
        "per_scenario": per_scenario,
        "failures": [{"scenario": r["scenario"], "seed": r["seed"], "run_id": r["run_id"],
                      "outcome": r["outcome"], "error": r.get("error", "")}
                     for r in rows if not passed(r)],
        "wall_time_s": round(wall_s, 1),
    }
