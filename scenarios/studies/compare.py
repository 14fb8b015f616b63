"""The paper's comparison: the NMPC and its two baselines on the same scenario and seed."""

from __future__ import annotations

import json
from pathlib import Path

from scenarios.loop.runner import R_B_M, run_scenario
from scenarios.scenario_file import Scenario

COMPARED = ("nmpc", "los-pid", "lexicographic")
COLUMNS = (
    ("controller", "controller", "{}"),
    ("reached goal", "reached_goal", "{}"),
    ("collision", "collision", "{}"),
    ("duration [s]", "duration_s", "{:.1f}"),
    ("min clearance [m]", "min_clearance_m", "{:.2f}"),
    ("time below R_b+d_p [s]", "time_below_desired_s", "{:.1f}"),
    ("J_c", "control_effort_Jc", "{:.0f}"),
    ("mean cross-track [m]", "mean_cross_track_m", "{:.2f}"),
    ("solve mean [ms]", "solve_mean_ms", "{:.2f}"),
    ("solve max [ms]", "solve_max_ms", "{:.1f}"),
)


def compare(scenario: Scenario, out_dir: Path, controllers=COMPARED, seed: int | None = None,
            plant: str = "fmu", progress=None, mcap: bool | None = False,
            cloud_points: int | None = None) -> list[dict]:
    """Run each controller into out_dir/<controller> (each with its run.mcap when `mcap`,
    see `run_scenario`); return one row of figures per run."""
    out_dir = Path(out_dir)
    rows, runs = [], {}
    for name in controllers:
        run_dir = out_dir / name
        result = run_scenario(scenario, run_dir, controller=name, seed=seed, plant=plant,
                              progress=progress(name) if progress else None, mcap=mcap,
                              cloud_points=cloud_points)
        s, t = result.summary, result.timing
        rows.append({**s, "solve_mean_ms": t["solve_ms"]["mean"], "solve_max_ms": t["solve_ms"]["max"]})
        runs[s["controller"]] = run_dir
    from scenarios.results.plots import plot_separation

    plot_separation(runs, R_B_M + scenario.d_p_m, out_dir / "separation.png",
                    f"{scenario.name}: separation, seed {rows[0]['seed']}")
    (out_dir / "compare.json").write_text(json.dumps(rows, indent=2) + "\n")
    (out_dir / "compare.md").write_text(markdown_table(rows, scenario) + "\n")
    return rows


def _cells(row: dict) -> list[str]:
    out = []
    for _, key, fmt in COLUMNS:
        v = row.get(key)
        out.append("-" if v is None else fmt.format(v))
    return out


def markdown_table(rows: list[dict], scenario: Scenario) -> str:
    head = [c[0] for c in COLUMNS]
    lines = [f"Scenario `{scenario.name}`, seed {rows[0]['seed']}, d_p = {scenario.d_p_m:g} m "
             f"(desired separation {R_B_M + scenario.d_p_m:g} m)", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(_cells(r)) + " |" for r in rows]
    return "\n".join(lines)


def text_table(rows: list[dict]) -> str:
    head = [c[0] for c in COLUMNS]
    cells = [_cells(r) for r in rows]
    widths = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(head)]
    fmt = "  ".join(f"{{:>{w}}}" for w in widths)
    return "\n".join([fmt.format(*head)] + [fmt.format(*c) for c in cells])
