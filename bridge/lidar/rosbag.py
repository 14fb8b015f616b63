"""ROS bags (ROS 2 `.mcap`/`.db3`, ROS 1 `.bag`) with `sensor_msgs/PointCloud2`, through
`rosbags` (no ROS installation needed), and writing such bags (tests, demos).

A sweep's time is its header stamp; per-point times come from the field drivers name them:
`t` (uint32 ns after the stamp, Ouster), `time` (float s after the stamp, velodyne_pointcloud),
`timestamp` (float64 s, absolute, Hesai) or `offset_time` (ns after the stamp, Livox).
A message that cannot be decoded is counted in `malformed` and skipped.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from controller.errors import InputError

from .recorded import RecordedSensor
from .scan import require

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
DATATYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
RELATIVE_TIME_FIELDS = {"t": 1e-9, "time": 1.0, "offset_time": 1e-9}


def bag_path(path) -> Path:
    """The path rosbags opens: a ROS 1 `.bag` file, or a ROS 2 bag's folder (given the folder
    or one of its `.mcap`/`.db3` files)."""
    p = Path(path)
    if p.is_file() and p.suffix in (".mcap", ".db3"):
        if not (p.parent / "metadata.yaml").exists():
            raise InputError(f"rosbag:{path}: a ROS 2 bag needs its metadata.yaml beside the "
                             f"{p.suffix} file (`ros2 bag reindex` writes one)")
        return p.parent
    if not p.exists():
        raise InputError(f"rosbag:{path}: no such bag")
    return p


def cloud_fields(msg) -> np.dtype:
    """The numpy record type of a PointCloud2's points."""
    order = ">" if msg.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for f in msg.fields:
        if f.datatype not in DATATYPES:
            raise ValueError(f"field {f.name!r}: datatype {f.datatype}")
        names.append(f.name)
        base = order + DATATYPES[f.datatype]
        formats.append(base if f.count <= 1 else (base, f.count))
        offsets.append(f.offset)
    return np.dtype({"names": names, "formats": formats, "offsets": offsets,
                     "itemsize": msg.point_step})


def decode_cloud(msg):
    """A PointCloud2 -> (stamp s, points (N, 3), times s (N,) or None); ValueError if malformed."""
    dtype = cloud_fields(msg)
    if not {"x", "y", "z"} <= set(dtype.names):
        raise ValueError("no x, y, z fields")
    n_rows, width, row = int(msg.height), int(msg.width), int(msg.row_step)
    data = np.asarray(msg.data, np.uint8)
    if row < width * msg.point_step or data.size < n_rows * row:
        raise ValueError(f"{data.size} bytes for {n_rows} rows of {row}")
    rows = data[:n_rows * row].reshape(n_rows, row)[:, :width * msg.point_step]
    rec = np.ascontiguousarray(rows).view(dtype).reshape(-1)
    pts = np.column_stack([rec["x"], rec["y"], rec["z"]]).astype(float)
    stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    times = None
    for name, scale in RELATIVE_TIME_FIELDS.items():
        if name in dtype.names:
            times = stamp + rec[name].astype(float) * scale
            break
    else:
        if "timestamp" in dtype.names:
            times = rec["timestamp"].astype(float)
    return stamp, pts, times


class RosbagSensor(RecordedSensor):
    """`rosbag:PATH`: the PointCloud2 messages of one topic (`topic`, or the bag's only one)."""

    def __init__(self, name: str, path, topic: str | None = None):
        super().__init__(name, f"rosbag:{path}")
        highlevel = require("rosbags.highlevel", self.spec)
        self.path = bag_path(path)
        try:
            reader = highlevel.AnyReader([self.path])
            reader.open()
        except Exception as exc:  # noqa: BLE001 - rosbags raises its own kinds for bad bags
            raise InputError(f"{self.spec}: cannot open the bag ({exc})") from None
        clouds = sorted({c.topic for c in reader.connections if c.msgtype == POINTCLOUD2})
        reader.close()
        if topic is None:
            if len(clouds) != 1:
                raise InputError(f"{self.spec}: {len(clouds)} PointCloud2 topics "
                                 f"({', '.join(clouds) or 'none'}); name one with topic = ...")
            topic = clouds[0]
        elif topic not in clouds:
            raise InputError(f"{self.spec}: no PointCloud2 topic {topic!r} (it has "
                             f"{', '.join(clouds) or 'none'})")
        self.topic = topic

    def sweeps(self):
        from rosbags.highlevel import AnyReader

        with AnyReader([self.path]) as reader:
            conns = [c for c in reader.connections if c.topic == self.topic]
            for conn, _, raw in reader.messages(connections=conns):
                try:
                    yield decode_cloud(reader.deserialize(raw, conn.msgtype))
                except Exception:  # noqa: BLE001 - a damaged message is counted, never fatal
                    self.malformed += 1
