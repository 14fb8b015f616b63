"""From options and configuration to the bridge's LiDAR source (`--lidar`, `--lidar-config`,
the scenario's `[lidar]` table)."""

from __future__ import annotations

import math

from controller.errors import InputError

from .config import LidarConfig, SensorConfig, load_lidar_config, parse_lidar_table, parse_source


def open_sensor(cfg: SensorConfig):
    """The sensor object for one configured sensor (checks files, ports and extras now)."""
    if cfg.kind == "replay":
        from .replay import ReplaySensor

        return ReplaySensor(cfg.name, cfg.target)
    if cfg.kind == "velodyne":
        from .velodyne import VelodyneUdpSensor

        return VelodyneUdpSensor(cfg.name, int(cfg.target), cfg.model, cfg.host)
    if cfg.kind == "velodyne-pcap":
        from .velodyne import VelodynePcapSensor

        return VelodynePcapSensor(cfg.name, cfg.target, cfg.model, cfg.clock)
    if cfg.kind == "rosbag":
        from .rosbag import RosbagSensor

        return RosbagSensor(cfg.name, cfg.target, cfg.topic)
    if cfg.kind in ("ouster", "ouster-pcap"):
        from .ouster import open_ouster

        return open_ouster(cfg)
    raise InputError(f"lidar {cfg.name!r}: 'sim' renders the whole simulated suite and cannot "
                     "be merged with other sensors")


DRIVER_MOUNT = (0.0, 0.0, 0.0, math.pi, 0.0, 0.0)
"""Where a source alone sits when the scenario names no `[sensors.replay_mount]`: the drivers
and ROS report x forward, y left, z up (REP 103), so an upright unit is the boat's frame
(x forward, y starboard, z down) rolled 180 deg. Recorded scans (`replay:`) have no known
convention and stay on the scenario's mount."""
DRIVER_KINDS = ("velodyne", "velodyne-pcap", "ouster", "ouster-pcap", "rosbag")


def default_mount(kind: str, scenario) -> tuple:
    """The mount of one `--lidar` source without a configuration: the scenario's
    `[sensors.replay_mount]` when it gives one (any value not zero), else, for a source whose
    convention is known (DRIVER_KINDS), that convention (DRIVER_MOUNT)."""
    mount = tuple(float(v) for v in getattr(scenario, "replay_mount", (0.0,) * 6))
    if any(mount) or kind not in DRIVER_KINDS:
        return mount
    return DRIVER_MOUNT


def lidar_config(specs, config_path, scenario) -> LidarConfig | None:
    """The configuration in force: the file, else the scenario's [lidar]; --lidar sources
    replace the configured ones in order (the same layout, live or recorded), or without a
    configuration each is one sensor on the scenario's replay_mount (a driver's or a ROS bag's
    on its convention when the scenario gives none: `default_mount`)."""
    specs = [s for s in ([specs] if isinstance(specs, str) else list(specs or ())) if s]
    config = None
    if config_path is not None:
        config = load_lidar_config(config_path)
    elif getattr(scenario, "lidar_table", None) is not None:
        base = scenario.path.parent if getattr(scenario, "path", None) else None
        config = parse_lidar_table(scenario.lidar_table, str(scenario.path or scenario.name),
                                   "lidar.", base)
    if config is None:
        if not specs or specs == ["sim"]:
            return None
        sensors = []
        for i, text in enumerate(specs):
            kind, target = parse_source(text)
            sensors.append(SensorConfig(f"lidar{i}" if len(specs) > 1 else "lidar", kind,
                                        target, default_mount(kind, scenario)))
        return LidarConfig(tuple(sensors), source="--lidar")
    if specs and specs != ["sim"]:
        from dataclasses import replace

        if len(specs) != len(config.sensors):
            raise InputError(f"--lidar given {len(specs)} times but {config.source} names "
                             f"{len(config.sensors)} sensors: give one source for each, in order")
        sensors = []
        for cfg, text in zip(config.sensors, specs):
            kind, target = parse_source(text)
            sensors.append(replace(cfg, kind=kind, target=target))
        config = replace(config, sensors=tuple(sensors))
    return config


def build_lidar(specs, config_path, scenario, seed: int | None = None):
    """The bridge's LiDAR source: the simulated suite (`sim`), or the merge of the sensors."""
    from .merge import MergedLidar
    from .sim import SimLidarSource

    config = lidar_config(specs, config_path, scenario)
    if config is None:
        return SimLidarSource(scenario, seed)
    if len(config.sensors) == 1 and config.sensors[0].kind == "sim":
        return SimLidarSource(scenario, seed)
    opened = []
    try:
        for cfg in config.sensors:
            opened.append(open_sensor(cfg))
    except BaseException:
        for s in opened:
            s.close()
        raise
    return MergedLidar(opened, [c.mount for c in config.sensors], [c.role for c in config.sensors],
                       config.silent_after_s, config.lost_after_s, config.deskew)
