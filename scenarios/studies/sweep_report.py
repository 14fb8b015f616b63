"""A study's `report.md` and plots: success rate, clearance and J_c per factor, the worst runs.

Success is the scenario's promise: the goal reached with every pass criterion of the file
and no collision. The soak rule is the product's: no exception, no collision, no controller
failure. Per factor (scenario, controller, each override that takes several values), each
value's runs pooled over everything else; the worst runs come with the command that
reproduces each one (`canalnav run FILE --seed S --set PATH=VALUE ...`).
"""

from __future__ import annotations

import math
import re
import shlex
from pathlib import Path

import numpy as np

from scenarios.studies.overrides import toml_value

WORST = 10  # runs listed in each "worst" table


def value_label(v) -> str:
    return v if isinstance(v, str) else toml_value(v)


def reproduce_command(row: dict) -> str:
    """The `canalnav run` line that makes this run again, with plots, in runs/. The scenario
    is the file the study ran (its path resolved from the study file's folder), named by its
    absolute path: the line works from any folder, not only from where the study started."""
    file = str(Path(row["scenario_file"]).resolve())
    parts = ["canalnav", "run", file, "--seed", str(row["seed"]), "--controller",
             row["controller"]]
    for path, value in row.get("overrides", []):
        parts += ["--set", f"{path}={toml_value(value)}"]
    parts += ["--out", f"runs/repro-{row['run_id']}"]
    return " ".join(shlex.quote(p) for p in parts)


def _figures(rows: list[dict], key: str) -> np.ndarray:
    v = [r.get(key) for r in rows if r.get("status") == "ok"]
    return np.array([x for x in v if isinstance(x, (int, float)) and math.isfinite(x)], float)


def _q(a: np.ndarray, q: float) -> str:
    return f"{np.quantile(a, q):.2f}" if len(a) else "-"


def factor_table(rows: list[dict], factor: str) -> list[dict]:
    """Per value of a factor: runs, raised, success rate, soak passes, clearance and J_c."""
    out = []
    for label, rs in _groups(rows, factor).items():
        clear, jc = _figures(rs, "min_clearance_m"), _figures(rs, "control_effort_Jc")
        out.append({
            "value": label, "runs": len(rs),
            "raised": sum(r["status"] != "ok" for r in rs),
            "success": sum(bool(r.get("success")) for r in rs),
            "soak_passed": sum(bool(r.get("soak_passed")) and r["status"] == "ok" for r in rs),
            "collisions": sum(bool(r.get("collision")) for r in rs),
            "clearance_min": _q(clear, 0.0), "clearance_p10": _q(clear, 0.1),
            "clearance_median": _q(clear, 0.5),
            "jc_median": _q(jc, 0.5), "jc_p90": _q(jc, 0.9),
        })
    return out


def _order(v):
    """Sort key of a factor's values: numbers by value (0.0 before 0.2), then the rest by
    their label (scenario and controller names alphabetically)."""
    if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
        return (0, float(v), "")
    return (1, 0.0, value_label(v) if v is not None else "")


def _groups(rows: list[dict], factor: str) -> dict[str, list]:
    """The runs by their value of the factor, in the values' order (`_order`)."""
    groups: dict[str, list] = {}
    for r in sorted(rows, key=lambda r: _order(r.get(factor))):
        groups.setdefault(value_label(r.get(factor)), []).append(r)
    return groups


def least_clearance_count(n: int) -> int:
    """How many runs "Least clearance" lists of n: the closest tenth, at least 3, at most
    WORST (a list of nearly every run says nothing about the worst)."""
    return min(n, WORST, max(3, math.ceil(n / 10)))


def _pct(k: int, n: int) -> str:
    return f"{k}/{n} ({100 * k / n:.0f} %)" if n else "0/0"


def write_report(study, outcome, out_dir: Path) -> Path:
    """report.md and one PNG per factor in `out_dir`, from the rows of `outcome`."""
    out_dir = Path(out_dir)
    by_id = {r.run_id: r for r in study.runs}
    rows = [dict(r, overrides=list(by_id[r["run_id"]].overrides))
            for r in outcome.rows if r["run_id"] in by_id]
    n = len(rows)
    ok = [r for r in rows if r["status"] == "ok"]
    lines = [f"# Study {study.name}", "",
             f"Study file `{study.spec_path}`; {len(study.runs)} runs"
             + (f" (a sample of {study.sample} of a grid of {study.grid_size}, seeded)"
                if study.sample else f" (the full grid)") + "."]
    lines += [f"This session: {len(outcome.executed)} runs on {outcome.where} in "
              f"{outcome.wall_s / 60:.1f} min"
              + (f" ({60 * len(outcome.executed) / outcome.wall_s:.2f} runs/min)"
                 if outcome.wall_s > 0 and outcome.executed else "")
              + (f"; {outcome.skipped} finished runs kept from before (--resume)"
                 if outcome.skipped else "") + ".", ""]
    missing = len(study.runs) - n
    lines += ["| | runs |", "| --- | --- |",
              f"| in the table | {n} of {len(study.runs)}"
              + (f" ({missing} not run yet: --resume)" if missing else "") + " |",
              f"| raised | {n - len(ok)} |",
              f"| success (goal reached, every criterion, no collision) | "
              f"{_pct(sum(bool(r['success']) for r in rows), n)} |",
              f"| soak rule (no exception, collision or controller failure) | "
              f"{_pct(sum(bool(r['soak_passed']) for r in ok), n)} |",
              f"| collisions | {sum(bool(r['collision']) for r in rows)} |",
              f"| controller failures | {sum(bool(r['controller_failed']) for r in rows)} |",
              ""]
    clear, jc = _figures(rows, "min_clearance_m"), _figures(rows, "control_effort_Jc")
    if len(clear):
        lines += [f"Min clearance over the runs: min {_q(clear, 0)} m, p10 {_q(clear, 0.1)} m, "
                  f"median {_q(clear, 0.5)} m; J_c median {_q(jc, 0.5)}, p90 {_q(jc, 0.9)}.", ""]
    lines += _sessions(out_dir)
    plots = []
    for factor in study.factors:
        table = factor_table(rows, factor)
        lines += [f"## By {factor}", "",
                  "| value | runs | success | soak rule | raised | collisions | "
                  "clearance min / p10 / median (m) | J_c median / p90 |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for t in table:
            lines.append(f"| {t['value']} | {t['runs']} | {_pct(t['success'], t['runs'])} | "
                         f"{t['soak_passed']} | {t['raised']} | {t['collisions']} | "
                         f"{t['clearance_min']} / {t['clearance_p10']} / "
                         f"{t['clearance_median']} | {t['jc_median']} / {t['jc_p90']} |")
        png = _plot_factor(rows, factor, out_dir)
        if png is not None:
            plots.append(png.name)
            lines += ["", f"![{factor}]({png.name})"]
        lines.append("")
    lines += _worst(rows)
    path = out_dir / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _sessions(out_dir: Path) -> list[str]:
    """The sessions that made the table (sessions.jsonl): where, runs, time, rate."""
    import json

    try:
        sessions = [json.loads(line) for line in
                    (out_dir / "sessions.jsonl").read_text().splitlines() if line.strip()]
    except (OSError, ValueError):
        return []
    if not sessions:
        return []
    out = ["## Sessions", "",
           "| started (UTC) | where | workers | runs | wall (min) | runs/min | mean run wall (s) "
           "| |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for s in sessions:
        out.append(f"| {s['started_at']} | {s['where']} | {s['workers']} | {s['runs']} | "
                   f"{s['wall_s'] / 60:.1f} | {s['runs_per_min']} | {s['mean_run_wall_s']} | "
                   f"{'interrupted' if s['interrupted'] else 'finished'} |")
    return out + [""]


def _worst(rows: list[dict]) -> list[str]:
    def entry(r, why):
        factors = ", ".join(f"{p} = {value_label(v)}" for p, v in r["overrides"])
        return (f"- `{r['run_id']}` {r['scenario']} seed {r['seed']} {r['controller']}"
                + (f" ({factors})" if factors else "") + f": {why}\n"
                f"  `{reproduce_command(r)}`")

    out = []
    raised = [r for r in rows if r["status"] != "ok"]
    if raised:
        out += ["## Runs that raised", ""]
        out += [entry(r, r.get("error") or r.get("outcome")) for r in raised[:2 * WORST]]
        if len(raised) > 2 * WORST:
            out.append(f"- ... and {len(raised) - 2 * WORST} more (results.json has each "
                       "traceback)")
        out.append("")
    failed = [r for r in rows if r["status"] == "ok" and not r.get("success")]
    if failed:
        out += ["## Runs that failed", ""]
        out += [entry(r, f"{r['outcome']}"
                      + (f"; {r['criteria_failed']}" if r.get("criteria_failed") else ""))
                for r in failed[:WORST]]
        if len(failed) > WORST:
            out.append(f"- ... and {len(failed) - WORST} more (results.csv)")
        out.append("")
    ok = [r for r in rows if r["status"] == "ok" and r.get("min_clearance_m") is not None]
    if ok:
        k = least_clearance_count(len(ok))
        out += ["## Least clearance", "",
                f"The {k} of {len(ok)} finished runs that came closest to a wall or a vessel "
                "(results.csv has every run's):", ""]
        out += [entry(r, f"min clearance {r['min_clearance_m']:.2f} m, "
                      f"{r['time_below_desired_s']} s below R_b + d_p, {r['outcome']}")
                for r in sorted(ok, key=lambda r: r["min_clearance_m"])[:k]]
        out.append("")
    return out


def _plot_factor(rows: list[dict], factor: str, out_dir: Path) -> Path | None:
    """factor-<name>.png: success rate, min clearance and J_c for each value of the factor."""
    from scenarios.results.plots import _pyplot

    groups = _groups(rows, factor)
    if not groups:
        return None
    labels = list(groups)
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    rate = [100 * sum(bool(r.get("success")) for r in groups[k]) / len(groups[k]) for k in labels]
    axes[0].bar(range(len(labels)), rate, color="tab:green")
    axes[0].set_ylim(0, 105)
    axes[0].set_ylabel("success (%)")
    for ax, key, name in ((axes[1], "min_clearance_m", "min clearance (m)"),
                          (axes[2], "control_effort_Jc", "J_c")):
        data = [_figures(groups[k], key) for k in labels]
        pos = [i for i, d in enumerate(data) if len(d)]
        if pos:
            ax.boxplot([data[i] for i in pos], positions=pos, widths=0.6)
        ax.set_ylabel(name)
    for ax in axes:
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, rotation=30 if max(map(len, labels)) > 6 else 0)
        ax.set_xlabel(factor)
        ax.set_xlim(-0.6, len(labels) - 0.4)
        ax.grid(alpha=0.3)
    fig.suptitle(f"by {factor} ({len(rows)} runs)")
    fig.tight_layout()
    path = out_dir / f"factor-{re.sub(r'[^A-Za-z0-9_.-]+', '_', factor)}.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
