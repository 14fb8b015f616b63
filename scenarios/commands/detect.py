"""`canalnav detect`: one simulated LiDAR scan and its wall detection, as a picture.

Like the paper's Fig. "LiDAR-based obstacle detection": (a) the raw merged cloud from above,
(b) from the side, (c) the cloud after the height and x, y crop, (d) the detected segments
over the true walls.
"""

from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser(
        "detect", help="simulate one LiDAR scan, detect walls, write a PNG",
        description="Places the boat S metres along the canal's centre line, renders one scan "
        "of the three simulated LiDARs, runs the wall detection and writes a figure like the "
        "paper's: raw cloud (top and side), cropped cloud, segments over the true walls.",
    )
    p.add_argument("--scenario", default=None, metavar="FILE",
                   help="scenario file (TOML) whose canal to use; 'demo' or none: the "
                   "built-in demo canal")
    p.add_argument("--at", type=float, required=True, metavar="S",
                   help="distance along the canal's centre line, metres (with --lidar: "
                   "seconds from the recording's first sweep)")
    p.add_argument("--offset", type=float, default=0.0,
                   help="offset from the centre line, metres, starboard positive (0)")
    p.add_argument("--speed", type=float, default=2.0,
                   help="boat speed, m/s, for the wake spray (2)")
    p.add_argument("--seed", type=int, default=0, help="noise seed (0)")
    p.add_argument("-o", "--out", default="detect.png", help="PNG to write (detect.png)")
    p.set_defaults(func=run)


def run(args) -> int:
    import numpy as np

    from controller.errors import InputError
    from controller.perception.detection import crop_mask, detect_segments, with_settings

    from ..results.detection_score import score_scan
    from ..scenario_file import load_world
    from ..sensors.lidar import LidarSimulator

    config = with_settings(getattr(args, "detect_set", None) or [])  # (the bridge adds
    world = load_world(args.scenario)  # --detect-set and --csv to this command)
    pose = world.pose_at(args.at, args.offset)
    sim = LidarSimulator(world, seed=args.seed)
    scan = sim.scan_labelled(pose, args.speed)
    segments = detect_segments(scan.points, pose, config)
    keep = crop_mask(scan.points, config)
    score = score_scan(world, sim, pose, segments, config)
    coverage = score.covered_m / score.visible_m if score.visible_m else float("nan")
    draw(args.out, world, sim, pose, scan, keep, segments, config,
         title=f"{world.name} canal, s = {args.at:g} m, seed {args.seed}: {len(segments)} "
         f"segments, {100 * coverage:.1f} % of the visible wall within 50 m covered")
    csv = getattr(args, "csv", None)
    if csv:
        body = detect_segments(scan.points, (0.0, 0.0, 0.0), config)  # the boat's frame
        try:
            np.savetxt(csv, body.reshape(-1, 4), delimiter=",", comments="", fmt="%.4f",
                       header="x_c_m,y_c_m,theta_rad,length_m")
        except OSError as exc:
            raise InputError(f"--csv {csv}: cannot write it: {exc.strerror or exc}") from None
    print(f"wrote {args.out}: {len(scan.points)} points, {int(np.count_nonzero(keep))} after "
          f"the crop, {len(segments)} segments, {100 * coverage:.1f} % of {score.visible_m:.0f} m "
          f"visible wall within 50 m covered, {score.false_m:.1f} m of "
          f"{score.detected_m:.0f} m detected farther than 1 m from a true surface")
    return 0


def draw(path, world, sim, pose, scan, keep, segments, config, title="", hull=None) -> None:
    """Write the four-panel figure (Agg backend, no display needed). `world` None (a
    recorded cloud: no truth known) leaves the true walls out of (d); `hull` is the
    boat's (default: the simulator's)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from controller.geometry import segments_to_endpoints

    pts = scan.points
    height = -pts[:, 2]
    fig = plt.figure(figsize=(16, 8.5), constrained_layout=True)
    grid = fig.add_gridspec(2, 3, width_ratios=[1.0, 1.0, 1.0])
    ax_top = fig.add_subplot(grid[:, 0])
    ax_side = fig.add_subplot(grid[0, 1])
    ax_crop = fig.add_subplot(grid[1, 1])
    ax_map = fig.add_subplot(grid[:, 2])
    view = 60.0
    if hull is None:
        from ..sensors.lidar import HullShape

        hull = sim.config.hull if sim is not None else HullShape()

    def boat_outline(ax):
        x0, x1, y0, y1 = hull.boxes[0][:4]
        ax.plot([y0, y1, y1, 0, y0, y0], [x0, x0, x1 - 1.2, x1, x1 - 1.2, x0], "k-", lw=0.8)

    sc = ax_top.scatter(pts[:, 1], pts[:, 0], c=height, s=0.15, cmap="viridis", vmin=-0.2,
                        vmax=8.0, rasterized=True)
    boat_outline(ax_top)
    ax_top.set(xlim=(-view, view), ylim=(-view, view), aspect="equal",
               xlabel="y, starboard (m)", ylabel="x, forward (m)",
               title=f"(a) raw cloud, top view: {len(pts)} points")
    fig.colorbar(sc, ax=ax_top, shrink=0.6, label="height above water (m)")

    ax_side.scatter(pts[:, 0], height, c=height, s=0.15, cmap="viridis", vmin=-0.2, vmax=8.0,
                    rasterized=True)
    for h in (config.min_height_m, config.max_height_m):
        ax_side.axhline(h, color="r", lw=0.8, ls="--")
    ax_side.set(xlim=(-view, view), ylim=(-1.0, 12.0), xlabel="x, forward (m)",
                ylabel="height above water (m)",
                title="(b) raw cloud, side view (dashed: the height band kept)")

    kept = pts[keep]
    ax_crop.scatter(kept[:, 1], kept[:, 0], s=0.3, c="k", rasterized=True)
    x0, x1 = config.hull_x_m
    x_w = x0 - config.wake_length_m
    for (ya, yb, xa, xb) in ((-config.hull_half_width_m, config.hull_half_width_m, x0, x1),
                             (-config.wake_half_width_m, config.wake_half_width_m, x_w, x0)):
        ax_crop.plot([ya, yb, yb, ya, ya], [xa, xa, xb, xb, xa], "r--", lw=0.8)
    ax_crop.set(xlim=(-view / 2, view / 2), ylim=(-view / 2, view / 2), aspect="equal",
                xlabel="y, starboard (m)", ylabel="x, forward (m)",
                title=f"(c) cropped: {len(kept)} points\n(dashed: hull and wake dropped)")

    x, y, psi = pose
    for k, line in enumerate(world.surfaces() if world is not None else ()):
        ax_map.plot(line[:, 1], line[:, 0], "-", color="0.6", lw=3.0,
                    label="true walls and obstacles" if k == 0 else None)
    a, b = segments_to_endpoints(segments)
    for k in range(len(segments)):
        ax_map.plot([a[k, 1], b[k, 1]], [a[k, 0], b[k, 0]], "-", color=f"C{k % 10}", lw=1.6,
                    label="detected segments" if k == 0 else None)
        ax_map.plot([a[k, 1], b[k, 1]], [a[k, 0], b[k, 0]], "k|", ms=4)
    c, s = np.cos(psi), np.sin(psi)
    bx = np.array([-3.95, 3.95, 3.95, -3.95, -3.95])
    by = np.array([-1.3, -1.3, 1.3, 1.3, -1.3])
    ax_map.fill(y + s * bx + c * by, x + c * bx - s * by, color="k")
    ring = np.linspace(0, 2 * np.pi, 200)
    ax_map.plot(y + 50 * np.sin(ring), x + 50 * np.cos(ring), "k:", lw=0.8, label="50 m")
    ax_map.set(xlim=(y - view, y + view), ylim=(x - view, x + view), aspect="equal",
               xlabel="east (m)" if world is not None else "y, starboard (m)",
               ylabel="north (m)" if world is not None else "x, forward (m)",
               title=f"(d) {len(segments)} segments" + (" over the true walls" if world
                                                         is not None else ""))
    ax_map.legend(loc="lower right", fontsize=8)
    if title:
        fig.suptitle(title)
    try:
        fig.savefig(path, dpi=110)
    except OSError as exc:  # a folder that is not there, a read-only one
        from controller.errors import InputError

        raise InputError(f"-o {path}: cannot write the figure: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)
