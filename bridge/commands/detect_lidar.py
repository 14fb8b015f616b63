"""`canalnav detect --lidar SOURCE [--lidar-config FILE] --at T`: the wall detection on a
recorded drive (a pcap, a bag, a scan folder) at a chosen time, in the paper-style figure of
`canalnav detect`, so the crop and Hough settings can be tuned on one's own data.

The recorded sources are the bridge's (bridge.lidar), which scenarios may not import: this
module adds the options to the `detect` command that scenarios/commands/detect.py registers
(the bridge's commands register after the other packages').
"""

from __future__ import annotations

RECORDED = ("replay", "velodyne-pcap", "ouster-pcap", "rosbag")


def register(sub) -> None:
    p = sub.choices.get("detect")
    if p is None:  # pragma: no cover - scenarios' detect is always there
        return
    p.add_argument("--lidar", action="append", metavar="SOURCE",
                   help="detect on a recording instead of a simulated scan: velodyne-pcap:FILE, "
                   "ouster-pcap:FILE, rosbag:PATH or replay:DIR; repeat for several sensors "
                   "(merged as on the bridge); --at is then seconds from the first sweep")
    p.add_argument("--lidar-config", metavar="FILE",
                   help="LiDAR configuration (TOML): the sensors' mounts (default: the "
                   "scenario's [lidar] table, else each source on its [sensors.replay_mount])")
    p.add_argument("--detect-set", action="append", default=[], metavar="NAME=VALUE",
                   help="a detection setting (controller.perception.detection.DetectionConfig, "
                   "e.g. max_height_m=1.2, hough_votes=8, hull_x_m=-5,5); repeatable")
    p.add_argument("--csv", metavar="FILE",
                   help="also write the detected segments (boat frame: x_c_m, y_c_m, "
                   "theta_rad, length_m) to FILE")
    simulated = p.get_default("func")
    p.set_defaults(func=lambda args: run(args) if args.lidar or args.lidar_config
                   else simulated(args))


def run(args) -> int:
    import numpy as np

    from controller.errors import InputError
    from controller.perception.detection import crop_mask, detect_segments
    from scenarios.commands.detect import draw

    from ..lidar.sources import build_lidar, lidar_config

    from controller.perception.detection import with_settings

    config = with_settings(args.detect_set)
    scenario = _scenario(args.scenario)
    layout = lidar_config(args.lidar or [], args.lidar_config, scenario)
    if layout is None:
        raise InputError("detect: --lidar SOURCE (or --lidar-config) names no recording")
    live = [s.source for s in layout.sensors if s.kind not in RECORDED]
    if live:
        raise InputError(f"detect --lidar: {', '.join(live)}: only recordings "
                         f"({', '.join(k + ':' for k in RECORDED)}) can be looked at in time")
    if not args.at >= 0:
        raise InputError(f"detect --at {args.at:g}: seconds from the first sweep, >= 0")
    source = build_lidar(args.lidar or [], args.lidar_config, scenario)
    pose = np.zeros(6)  # the boat's own frame: north = forward
    try:
        cloud = source.scan(float(args.at), pose)
    finally:
        source.close()
    if cloud is None or not len(cloud):
        raise InputError(f"detect: no sweep of {source.name} at or before {args.at:g} s "
                         "from its first")
    segments = detect_segments(cloud, pose[:3], config)
    keep = crop_mask(cloud, config)
    if not keep.any():  # say why nothing could be detected, instead of 0 segments alone
        import sys

        z = np.asarray(cloud, float)[:, 2]
        print(f"canalnav detect: warning: the crop kept none of the {len(cloud)} points (their "
              f"height below the boat: {np.percentile(-z, 5):.1f} to {np.percentile(-z, 95):.1f} m "
              f"for 90 % of them; the band is {config.min_height_m:g}-{config.max_height_m:g} m "
              "above the water). Check the mount: a sensor in ROS's convention (x forward, "
              "y left, z up) needs roll_deg = 180 on the boat's (x forward, y starboard, z "
              "down)", file=sys.stderr)

    class Scan:
        points = cloud

    lengths = float(np.sum(segments[:, 3])) if len(segments) else 0.0
    draw(args.out, None, None, pose[:3], Scan, keep, segments, config,
         title=f"{source.name} at {args.at:g} s: {len(segments)} segments, "
         f"{lengths:.0f} m of wall")
    if args.csv:
        np.savetxt(args.csv, np.asarray(segments, float).reshape(-1, 4), delimiter=",",
                   header="x_c_m,y_c_m,theta_rad,length_m", comments="", fmt="%.4f")
    malformed = sum(source.malformed.values())
    print(f"wrote {args.out}: {len(cloud)} points at {args.at:g} s, "
          f"{int(np.count_nonzero(keep))} after the crop, {len(segments)} segments "
          f"({lengths:.1f} m of wall), {malformed} malformed packets or messages skipped")
    return 0


def _scenario(path):
    """The scenario for mounts and its [lidar] table, or a stand-in with none."""
    if path is None or path == "demo":
        from types import SimpleNamespace

        return SimpleNamespace(replay_mount=(0.0,) * 6, lidar_table=None, path=None,
                               name="detect")
    from scenarios.scenario_file import load_scenario

    return load_scenario(path)
