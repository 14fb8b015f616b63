"""The LiDAR configuration: which sensors, where they sit, where their data come from.

A TOML file (`--lidar-config FILE`) or the scenario's `[lidar]` table, for example (the
paper's layout in lidar_paper_layout.toml beside this module):

    silent_after_s = 0.3   # a sensor without a new sweep this long leaves the merge
    lost_after_s = 1.0     # every sensor silent this long: failsafe "perception lost"
    deskew = true

    [[sensor]]             # in a scenario: [[lidar.sensor]]
    name = "front"
    source = "velodyne:2368"
    model = "VLP-16"
    role = "front"
    mount = { x_m = 3.5, y_m = 0.0, z_m = -1.3, roll_deg = 180, pitch_deg = 0, yaw_deg = 0 }

The mount is `[sensors.replay_mount]`'s convention: the sensor's origin in the body frame
(x forward, y starboard, z down, metres) and its orientation, R = Rz(yaw) Ry(pitch) Rx(roll);
a unit reporting x forward, y left, z up (as every driver here does) standing upright has
roll 180 deg. Errors name the file and the field.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from controller.errors import InputError

KINDS = ("sim", "replay", "velodyne", "velodyne-pcap", "ouster", "ouster-pcap", "rosbag")
ROLES = ("front", "port", "starboard", "rear", "side", "all-round")
SENSOR_KEYS = {"name", "source", "role", "mount", "model", "metadata", "meta", "topic", "clock",
               "lidar_port", "host"}
MOUNT_KEYS = {"x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg"}
TOP_KEYS = {"sensor", "silent_after_s", "lost_after_s", "deskew"}


@dataclass(frozen=True)
class SensorConfig:
    """One sensor: `kind` and `target` from its source (`velodyne-pcap:drive.pcap` ->
    ("velodyne-pcap", "drive.pcap")), its mount (x, y, z m, roll, pitch, yaw rad)."""

    name: str
    kind: str
    target: str
    mount: tuple = (0.0,) * 6
    role: str = "front"
    model: str | None = None  # Velodyne model (velodyne-decoder's names: VLP-16, HDL-32E, ...)
    metadata: str | None = None  # Ouster sensor metadata JSON (key `meta` or `metadata`)
    topic: str | None = None  # rosbag: the PointCloud2 topic (default: the only one)
    clock: str = "host"  # velodyne-pcap: "host" (capture times) or "sensor" (packet stamps)
    lidar_port: int | None = None  # ouster: UDP port for lidar data
    host: str = "0.0.0.0"  # velodyne: address to listen on

    @property
    def source(self) -> str:
        return self.kind if self.kind == "sim" else f"{self.kind}:{self.target}"


@dataclass(frozen=True)
class LidarConfig:
    sensors: tuple[SensorConfig, ...] = ()
    silent_after_s: float = 0.3
    lost_after_s: float = 1.0
    deskew: bool = True
    source: str = ""


def parse_source(text: str, where: str = "--lidar") -> tuple[str, str]:
    """`velodyne:2368` -> ("velodyne", "2368"); InputError lists the kinds."""
    text = str(text).strip()
    if text == "sim":
        return "sim", ""
    kind, sep, target = text.partition(":")
    if kind in KINDS and kind != "sim" and sep and target:
        if kind == "velodyne" and not (target.isdigit() and 0 < int(target) < 65536):
            raise InputError(f"{where} {text!r}: velodyne:PORT needs a UDP port number")
        return kind, target
    raise InputError(f"{where} {text!r}: expected 'sim', 'replay:DIR', 'velodyne:PORT', "
                     "'velodyne-pcap:FILE', 'ouster:HOST', 'ouster-pcap:FILE' or 'rosbag:PATH'")


def load_lidar_config(path) -> LidarConfig:
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(f"--lidar-config {path}: cannot read it ({exc.strerror})") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({exc})") from None
    if set(doc) == {"lidar"}:  # the same text as a scenario's [lidar] table
        return parse_lidar_table(doc["lidar"], str(path), "lidar.", path.parent)
    return parse_lidar_table(doc, str(path), "", path.parent)


def parse_lidar_table(table: dict, source: str, prefix: str = "lidar.", base: Path | None = None
                      ) -> LidarConfig:
    """A `[lidar]` table (of a scenario or a config file) -> LidarConfig; relative paths are
    taken from `base` (the file's folder)."""

    def err(key, msg):
        return InputError(f"{source}: field {prefix + key!r}: {msg}")

    if not isinstance(table, dict):
        raise InputError(f"{source}: field {prefix.rstrip('.') or 'lidar'!r} must be a table")
    for key in table:
        if key not in TOP_KEYS:
            raise err(key, f"unknown field (known: {', '.join(sorted(TOP_KEYS))})")
    silent = _number(table, "silent_after_s", 0.3, err)
    lost = _number(table, "lost_after_s", 1.0, err)
    deskew = table.get("deskew", True)
    if not isinstance(deskew, bool):
        raise err("deskew", f"expected true or false, got {deskew!r}")
    rows = table.get("sensor", [])
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        raise err("sensor", "expected an array of tables ([[sensor]])")
    if not rows:
        raise err("sensor", "no sensors: give at least one [[sensor]] with a name and a source")
    sensors, names = [], set()
    for i, row in enumerate(rows):
        sensors.append(_sensor(row, f"{prefix}sensor[{i}].", source, base))
        if sensors[-1].name in names:
            raise InputError(f"{source}: field '{prefix}sensor[{i}].name': "
                             f"{sensors[-1].name!r} is used twice")
        names.add(sensors[-1].name)
    return LidarConfig(tuple(sensors), silent, lost, deskew, source)


def _number(table, key, default, err, low=0.0):
    v = table.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= low:
        raise err(key, f"expected a positive number of seconds, got {v!r}")
    return float(v)


def _sensor(row: dict, prefix: str, source: str, base: Path | None) -> SensorConfig:
    def err(key, msg):
        return InputError(f"{source}: field {prefix + key!r}: {msg}")

    for key in row:
        if key not in SENSOR_KEYS:
            raise err(key, f"unknown field (known: {', '.join(sorted(SENSOR_KEYS))})")
    for key in ("name", "source"):
        if not isinstance(row.get(key), str) or not row[key].strip():
            raise err(key, "is required (a non-empty string)")
    try:
        kind, target = parse_source(row["source"], "source")
    except InputError as exc:
        raise err("source", str(exc).split(": ", 1)[1]) from None
    if kind in ("replay", "velodyne-pcap", "ouster-pcap", "rosbag") and base is not None:
        target = str(base / target) if not Path(target).is_absolute() else target
    role = row.get("role", "front")
    if role not in ROLES:
        raise err("role", f"{role!r} is not one of {', '.join(ROLES)}")
    mount = row.get("mount", {})
    if not isinstance(mount, dict):
        raise err("mount", "expected a table of x_m, y_m, z_m, roll_deg, pitch_deg, yaw_deg")
    for key in mount:
        if key not in MOUNT_KEYS:
            raise err(f"mount.{key}", f"unknown field (known: {', '.join(sorted(MOUNT_KEYS))})")
    values = []
    for key in ("x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg"):
        v = mount.get(key, 0.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise err(f"mount.{key}", f"expected a number, got {v!r}")
        values.append(float(v) if key.endswith("_m") else math.radians(float(v)))
    if "meta" in row and "metadata" in row:
        raise err("meta", "give the Ouster metadata JSON once ('meta' or 'metadata')")
    said = {"metadata": "meta" if "meta" in row else "metadata"}  # the name the file used
    row = {("metadata" if k == "meta" else k): v for k, v in row.items()}
    strings = {}
    for key in ("model", "metadata", "topic", "host", "clock"):
        v = row.get(key)
        if v is not None and not isinstance(v, str):
            raise err(said.get(key, key), f"expected a string, got {v!r}")
        strings[key] = v
    if strings["clock"] not in (None, "host", "sensor"):
        raise err("clock", f"{strings['clock']!r}: expected 'host' (the capture's times) or "
                  "'sensor' (the packets' own stamps)")
    if strings["metadata"] and base is not None and not Path(strings["metadata"]).is_absolute():
        strings["metadata"] = str(base / strings["metadata"])
    port = row.get("lidar_port")
    if port is not None and not (isinstance(port, int) and 0 < port < 65536):
        raise err("lidar_port", f"expected a UDP port number, got {port!r}")
    return SensorConfig(row["name"].strip(), kind, target, tuple(values), role,
                        strings["model"], strings["metadata"], strings["topic"],
                        strings["clock"] or "host", port, strings["host"] or "0.0.0.0")
