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
HULL_RADIUS_M = 3.0  # R_b of the hull circles


def read_log(path: Path) -> dict[str, np.ndarray]:
    """Numeric columns of log.csv as arrays (the status column as strings)."""
    with Path(path).open() as fh:
        rows = list(csv.DictReader(fh))
    cols: dict[str, np.ndarray] = {}
    for key in (rows[0].keys() if rows else []):
        values = [r[key] for r in rows]
        try:  # an empty cell is "not known" (e.g. no water estimate)
            cols[key] = np.array([v if v != "" else "nan" for v in values], float)
        except ValueError:
            cols[key] = np.array(values)
    return cols


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _figure(*args, **kwargs):
    plt = _pyplot()
    return plt, plt.subplots(*args, **kwargs)


def plot_trajectory(run_dir: Path, outlines, waypoints, out: Path, title: str = "",
                    window_m: float = 70.0, vessels=()) -> Path:
    """The whole map with the track, and beside it a close-up of each snapshot (a square of
    `window_m` around the boat): the segments the controller saw, its predicted horizon and
    the hull circles, as the paper's snapshot figures; other vessels' tracks on the map, and
    their hulls (true) and tracks (as perceived) in the close-ups."""
    log = read_log(run_dir / "log.csv")
    snaps = json.loads((run_dir / "snapshots.json").read_text())
    n = len(snaps)
    cols = 2 if n > 1 else 1
    rows = max(1, -(-n // cols))
    plt = _pyplot()
    fig = plt.figure(figsize=(4.2 + 4.2 * cols, 4.2 * rows if n else 6.0))
    grid = fig.add_gridspec(rows, 1 + cols, width_ratios=[1.0] + [1.0] * cols)
    overview = fig.add_subplot(grid[:, 0])
    _draw_map(overview, outlines, waypoints, log)
    t_end = float(log["time_s"][-1]) if len(log["time_s"]) else 0.0
    for k, v in enumerate(vessels):
        seen = v.times <= t_end
        overview.plot(v.poses[seen, 1], v.poses[seen, 0], ":", color="tab:brown", lw=1.0,
                      label="other vessels" if k == 0 else None)
    overview.set_aspect("equal", adjustable="datalim")
    for j, sn in enumerate(snaps):
        x, y = sn["state"][:2]
        overview.annotate(str(j + 1), (y, x), fontsize=9, color="tab:red", weight="bold",
                          xytext=(4, 0), textcoords="offset points")
    overview.set_title(title or "trajectory", fontsize=10)
    overview.legend(loc="best", fontsize=7)
    for j, sn in enumerate(snaps):
        ax = fig.add_subplot(grid[j // cols, 1 + j % cols])
        _draw_map(ax, outlines, waypoints, log, legend=False)
        _draw_snapshot(ax, sn, labels=(j == 0))
        for k, v in enumerate(vessels):
            hull = v.outline_at(sn["time_s"])
            ring = np.vstack([hull, hull[:1]])
            ax.fill(ring[:, 1], ring[:, 0], color="tab:brown", alpha=0.5,
                    label="vessel (true)" if j == 0 and k == 0 else None)
        x, y = sn["state"][:2]
        ax.set_xlim(y - window_m / 2, y + window_m / 2)
        ax.set_ylim(x - window_m / 2, x + window_m / 2)
        ax.set_aspect("equal", adjustable="box")
        ax.set_title(f"{j + 1}: t = {sn['time_s']:.0f} s", fontsize=9)
        if j == 0:
            ax.legend(loc="lower left", fontsize=6)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def _draw_map(ax, outlines, waypoints, log, legend: bool = True) -> None:
    for i, line in enumerate(outlines):
        line = np.asarray(line)
        ax.plot(line[:, 1], line[:, 0], color="0.25", lw=1.2, label="walls" if i == 0 else None)
    wp = np.asarray(waypoints)
    ax.plot(wp[:, 1], wp[:, 0], "--", color="tab:blue", lw=0.9, label="waypoint path")
    ax.plot(log["true_y_m"], log["true_x_m"], color="tab:green", lw=1.2, label="boat (true)")
    ax.set_xlabel("east [m]", fontsize=8)
    ax.set_ylabel("north [m]", fontsize=8)
    ax.tick_params(labelsize=7)


def _draw_snapshot(ax, sn: dict, labels: bool) -> None:
    """Segments seen, predicted horizon and the hull circles (R_b = 3 m) at one instant."""
    for i, (xc, yc, th, ln) in enumerate(np.asarray(sn["segments"]).reshape(-1, 4)):
        dx, dy = 0.5 * ln * np.cos(th), 0.5 * ln * np.sin(th)
        ax.plot([yc - dy, yc + dy], [xc - dx, xc + dx], color="tab:purple", lw=2.5, alpha=0.7,
                label="segments seen" if labels and i == 0 else None)
    if sn["predicted"]:
        pred = np.asarray(sn["predicted"])
        ax.plot(pred[:, 1], pred[:, 0], ".-", color="tab:orange", ms=3, lw=1,
                label="predicted horizon" if labels else None)
    for i, (tx, ty, th, ln, wd) in enumerate(np.asarray(sn.get("tracks") or [], float)
                                             .reshape(-1, 5)):
        c, s = np.cos(th), np.sin(th)
        box = np.array([[ln, wd], [-ln, wd], [-ln, -wd], [ln, -wd], [ln, wd]]) / 2
        bx, by = tx + c * box[:, 0] - s * box[:, 1], ty + s * box[:, 0] + c * box[:, 1]
        ax.plot(by, bx, color="tab:red", lw=1.0,
                label="vessel tracks" if labels and i == 0 else None)
    x, y, psi = sn["state"][:3]
    for k, off in enumerate((2.0, -2.0)):
        cx, cy = x + off * np.cos(psi), y + off * np.sin(psi)
        ax.add_patch(_circle((cy, cx), HULL_RADIUS_M,
                             label="hull circles" if labels and k == 0 else None))


def _circle(centre, radius, label=None):
    from matplotlib.patches import Circle

    return Circle(centre, radius, fill=False, color="tab:red", lw=1.0, label=label)


def plot_separation(runs: dict[str, Path], desired_m: float, out: Path, title: str = "") -> Path:
    """Separation over time for one run or several (a comparison), both hull circles each."""
    plt, (fig, ax) = _figure(figsize=(10, 4))
    colors = ["tab:blue", "tab:green", "tab:red", "tab:purple"]
    for i, (color, (name, run_dir)) in enumerate(zip(colors, runs.items())):
        log = read_log(Path(run_dir) / "log.csv")
        if i == 0 and "canal_width_m" in log:
            _shade_narrow(ax, log["time_s"], log["canal_width_m"] < 2 * desired_m,
                          f"canal narrower than {2 * desired_m:g} m")
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


def _shade_narrow(ax, t, narrow, label: str) -> None:
    """Grey bands over the times where `narrow` holds."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], narrow.astype(int), [0]])))
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.1
    for k, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
        ax.axvspan(t[a], t[b - 1] + dt, color="0.88", lw=0, label=label if k == 0 else None)


def plot_states(run_dir: Path, out: Path, title: str = "") -> Path:
    log = read_log(run_dir / "log.csv")
    t = log["time_s"]
    water = "current_est_n_mps" in log and log["current_est_n_mps"].dtype.kind == "f" \
        and np.isfinite(log["current_est_n_mps"]).any()
    plt, (fig, axes) = _figure(4 if water else 3, 2, figsize=(11, 9 if water else 7),
                               sharex=True)
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
    if water:
        for ax, axis, name in zip(axes[3], ("n", "e"), ("north", "east")):
            est, sigma = log[f"current_est_{axis}_mps"], log[f"current_sigma_{axis}_mps"]
            ax.fill_between(t, est - 2 * sigma, est + 2 * sigma, color="C1", alpha=0.2,
                            lw=0, label="estimate +- 2 sigma")
            ax.plot(t, log[f"current_true_{axis}_mps"], label="true")
            ax.plot(t, est, lw=0.8, color="C1", label="estimated")
            ax.set_ylabel(f"current {name} [m/s]")
        axes[3, 0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(title or "states and inputs")
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out
