"""PNG plots of a run, like the paper's figures, drawn from the files a run leaves behind.

- `trajectory.png`: the canal map, the waypoint path, the boat's track, and at a few instants
  the detected segments and the predicted horizon (paper Figs. "Snapshot images").
- `separation.png`: distance from both hull circles to the nearest true wall over time, with
  the desired separation R_b + d_p, the boat's breadth and twice it (paper Fig. separation).
- `states.png`: states and inputs over time (paper Fig. "Simulation results").
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

BREADTH_M = 2.6  # the paper's boat


def read_log(path: Path) -> dict[str, np.ndarray]:
    """Numeric columns of log.csv as arrays (the status column as strings)."""
    with Path(path).open() as fh:
        rows = list(csv.DictReader(fh))
    cols: dict[str, np.ndarray] = {}
    for key in (rows[0].keys() if rows else []):
        values = [r[key] for r in rows]
        try:
            cols[key] = np.array(values, float)
        except ValueError:
            cols[key] = np.array(values)
    return cols


def _figure(*args, **kwargs):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt, plt.subplots(*args, **kwargs)


def plot_trajectory(run_dir: Path, outlines, waypoints, out: Path, title: str = "") -> Path:
    log = read_log(run_dir / "log.csv")
    snaps = json.loads((run_dir / "snapshots.json").read_text())
    plt, (fig, ax) = _figure(figsize=(10, 8))
    for i, line in enumerate(outlines):
        line = np.asarray(line)
        ax.plot(line[:, 1], line[:, 0], color="0.25", lw=1.5, label="walls" if i == 0 else None)
    wp = np.asarray(waypoints)
    ax.plot(wp[:, 1], wp[:, 0], "--", color="tab:blue", lw=1, label="waypoint path")
    ax.plot(log["true_y_m"], log["true_x_m"], color="tab:green", lw=1.5, label="boat (true)")
    labelled = False
    for j, sn in enumerate(snaps):
        for xc, yc, th, ln in np.asarray(sn["segments"]).reshape(-1, 4):
            dx, dy = 0.5 * ln * np.cos(th), 0.5 * ln * np.sin(th)
            ax.plot([yc - dy, yc + dy], [xc - dx, xc + dx], color="k", lw=3, alpha=0.5,
                    label=None if labelled else "segments seen by the controller")
            labelled = True
        if sn["predicted"]:
            pred = np.asarray(sn["predicted"])
            ax.plot(pred[:, 1], pred[:, 0], ".-", color="tab:orange", ms=3, lw=1,
                    label="predicted horizon" if j == 0 else None)
        x, y = sn["state"][:2]
        ax.annotate(f"t={sn['time_s']:.0f}s", (y, x), fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_title(title or "trajectory")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def plot_separation(runs: dict[str, Path], desired_m: float, out: Path, title: str = "") -> Path:
    """Separation over time for one run or several (a comparison), both hull circles each."""
    plt, (fig, ax) = _figure(figsize=(10, 4))
    colors = ["tab:blue", "tab:green", "tab:red", "tab:purple"]
    for color, (name, run_dir) in zip(colors, runs.items()):
        log = read_log(Path(run_dir) / "log.csv")
        ax.plot(log["time_s"], log["clearance_bow_m"], ":", color=color, label=f"{name}: p_b (bow)")
        ax.plot(log["time_s"], log["clearance_stern_m"], "-", color=color, label=f"{name}: p_s (stern)")
    ax.axhline(desired_m, color="k", ls="--", lw=1, label=f"desired R_b + d_p = {desired_m:g} m")
    ax.axhline(BREADTH_M, color="tab:orange", ls="--", lw=1, label="breadth")
    ax.axhline(2 * BREADTH_M, color="tab:red", ls="--", lw=1, label="2 x breadth")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("distance to nearest wall [m]")
    ax.set_title(title or "separation")
    ax.legend(loc="upper right", fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def plot_states(run_dir: Path, out: Path, title: str = "") -> Path:
    log = read_log(run_dir / "log.csv")
    t = log["time_s"]
    plt, (fig, axes) = _figure(3, 2, figsize=(11, 7), sharex=True)
    panels = [
        ("true_u_mps", "est_u_mps", "u [m/s]"),
        ("true_v_mps", "est_v_mps", "v [m/s]"),
        ("true_psi_rad", "est_psi_rad", "heading [deg]"),
        ("true_r_radps", "est_r_radps", "r [deg/s]"),
    ]
    for ax, (true, est, label) in zip(axes.flat, panels):
        scale = np.degrees(1.0) if "deg" in label else 1.0
        ax.plot(t, log[true] * scale, label="true")
        ax.plot(t, log[est] * scale, lw=0.8, alpha=0.8, label="estimated")
        ax.set_ylabel(label)
    axes[0, 0].legend(fontsize=8)
    ax = axes[2, 0]
    ax.plot(t, log["nT_cmd_pct"], label="nT command")
    ax.plot(t, log["nS_cmd_pct"], label="nS command")
    ax.plot(t, log["nT_actual_pct"], ":", label="nT actual")
    ax.plot(t, log["nS_actual_pct"], ":", label="nS actual")
    ax.set_ylabel("command [%]")
    ax.legend(fontsize=7, ncol=2)
    ax = axes[2, 1]
    ax.plot(t, log["dnT_pctps"], label="dnT")
    ax.plot(t, log["dnS_pctps"], label="dnS")
    ax.set_ylabel("rate [%/s]")
    ax.legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(title or "states and inputs")
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out
