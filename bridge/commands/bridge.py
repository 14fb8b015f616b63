"""`canalnav bridge`: the NMPC driving an ArduPilot Rover boat over MAVLink."""

from __future__ import annotations

import argparse


def register(sub) -> None:
    p = sub.add_parser(
        "bridge", help="drive an ArduPilot Rover boat over MAVLink with the NMPC",
        description="Connect to an ArduPilot Rover (boat) autopilot, check that it will obey "
        "RC overrides, wait for a usable EKF position, then run the NMPC at 10 Hz on the EKF "
        "state and the LiDAR's segments, sending throttle and steering as "
        "RC_CHANNELS_OVERRIDE. Never arms or changes mode unless asked. On a lost link, a "
        "stale state, a controller failure or Ctrl-C it sends neutral commands, releases the "
        "overrides, sets HOLD (with --mode) and tells the ground station. Exit status: 0 goal "
        "reached, 1 stopped (time limit, failsafe), 2 bad input or no answer, 3 pre-flight "
        "refused, 130 Ctrl-C.",
    )
    p.add_argument("--connect", required=True, metavar="URL",
                   help="pymavlink connection: udpin:0.0.0.0:14550, udpout:HOST:PORT, "
                   "tcp:HOST:PORT, or a serial device with baud, /dev/ttyACM0,115200")
    p.add_argument("--scenario", required=True, metavar="FILE",
                   help="scenario file: waypoints, target speed, d_p, controller options, origin")
    p.add_argument("--lidar", action="append", metavar="SOURCE",
                   help="sim (the scenario's canal seen at the reported pose; default), "
                   "replay:DIR (one .npy/.bin scan per file, named by its timestamp in ns), "
                   "velodyne:PORT (live UDP), velodyne-pcap:FILE, ouster:HOST, "
                   "ouster-pcap:FILE (metadata in the config), rosbag:PATH (ROS 2 .mcap/.db3 "
                   "or ROS 1 .bag, PointCloud2); repeat for several sensors (merged). With "
                   "--lidar-config or a scenario [lidar] table, one for each configured "
                   "sensor, in order, replaces its source")
    p.add_argument("--lidar-config", metavar="FILE",
                   help="LiDAR configuration (TOML): each sensor's name, source, mount and "
                   "role, silence and loss times (see bridge/lidar/lidar_paper_layout.toml); "
                   "default: the scenario's [lidar] table, if any")
    p.add_argument("--origin", metavar="LAT,LON[,ALT]",
                   help="where the scenario's (0, 0) is on the Earth (degrees, metres; a "
                   "negative latitude as it is, -35.36,149.17); default: the "
                   "scenario's [origin]. One of the two is required: ArduPilot's local frame "
                   "starts wherever its first GPS fix came")
    p.add_argument("--arm", action="store_true", help="arm the autopilot (never without this)")
    p.add_argument("--mode", metavar="NAME",
                   help="switch to this mode (e.g. MANUAL) before driving, HOLD on a failsafe; "
                   "without it the autopilot must already be in MANUAL")
    p.add_argument("--signing-key", metavar="FILE",
                   help="MAVLink 2 signing key (32 raw bytes, 64 hex characters, or a "
                   "passphrase); unsigned messages are then ignored")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds of control")
    p.add_argument("--resume", action="store_true",
                   help="after a failsafe, wait for the link and state to return and continue")
    p.add_argument("--log", metavar="DIR", help="write mavlink.tlog, steps.csv, segments.csv, "
                   "tracks.csv and run.mcap (for Foxglove, with the viz extra) here")
    p.add_argument("--live", metavar="[HOST:]PORT",
                   help="serve the steps live to Foxglove (Foxglove WebSocket, ws://HOST:PORT: "
                   "pose, LiDAR cloud, segments, plan, figures); HOST is 127.0.0.1 (this "
                   "machine only) unless given, e.g. 0.0.0.0:8765 to reach it over the boat's "
                   "network. Never slows the 10 Hz loop (a slow viewer loses messages). Needs "
                   "pip install 'canalnav[viz]'")
    from scenarios.commands.arguments import whole_number
    from scenarios.results.mcap_log import DEFAULT_CLOUD_POINTS

    p.add_argument("--mcap", action=argparse.BooleanOptionalAction, default=None,
                   help="write run.mcap into --log DIR (default: when the viz extra is "
                   "installed, which --mcap then requires)")
    p.add_argument("--mcap-points", type=whole_number(0), default=DEFAULT_CLOUD_POINTS,
                   metavar="N", help=f"LiDAR points kept per scan (default {DEFAULT_CLOUD_POINTS})")
    p.add_argument("--system-id", type=int, default=255, metavar="N",
                   help="our MAVLink system id (default 255: ArduPilot's GCS id, the only one "
                   "whose overrides it obeys)")
    p.add_argument("--component-id", type=int, default=191, metavar="N",
                   help="our component id (default 191, MAV_COMP_ID_ONBOARD_COMPUTER)")
    p.add_argument("--target-system", type=int, metavar="N",
                   help="the autopilot's system id (default: the first autopilot heard)")
    p.add_argument("--link-timeout", type=float, default=3.0, metavar="S",
                   help="link lost after S seconds without a message (default 3)")
    p.add_argument("--stale-after", type=float, default=1.0, metavar="S",
                   help="state stale when older than S seconds (default 1)")
    p.add_argument("--ekf-timeout", type=float, default=120.0, metavar="S",
                   help="give up if the EKF has no usable position after S seconds (default 120)")
    p.add_argument("--heartbeat-timeout", type=float, default=30.0, metavar="S",
                   help="give up if no autopilot heartbeat comes within S seconds (default 30)")
    p.add_argument("--speedup", type=float, default=1.0, metavar="K",
                   help="run the clock K times faster (against a sped-up simulated autopilot)")
    p.add_argument("--seed", type=int, help="simulated LiDAR noise seed (default: the scenario's)")
    p.set_defaults(func=run)


def run(args) -> int:
    from bridge.onboard.loop import BridgeOptions, parse_origin, run_bridge
    from scenarios.results.foxglove_messages import require_viz
    from scenarios.results.mcap_log import parse_live

    live = parse_live(args.live) if args.live else None
    if live is not None or args.mcap:
        require_viz()

    options = BridgeOptions(
        connect=args.connect, scenario=args.scenario, lidar=tuple(args.lidar or ("sim",)),
        lidar_config=args.lidar_config, arm=args.arm,
        mode=args.mode, signing_key=args.signing_key, duration_s=args.duration,
        resume=args.resume, log_dir=args.log, system_id=args.system_id,
        component_id=args.component_id, target_system=args.target_system,
        link_timeout_s=args.link_timeout, stale_s=args.stale_after, speedup=args.speedup,
        ekf_timeout_s=args.ekf_timeout, heartbeat_timeout_s=args.heartbeat_timeout,
        seed=args.seed, origin=None if args.origin is None else parse_origin(args.origin),
        mcap=args.mcap, live=live, cloud_points=args.mcap_points,
    )
    result = run_bridge(options)
    print(f"canalnav bridge: {result.reason} after {result.steps} control steps"
          + (f"; failsafes: {'; '.join(result.failsafes)}" if result.failsafes else ""))
    return result.exit_code
