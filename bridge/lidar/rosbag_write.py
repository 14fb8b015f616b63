"""Writing sweeps as `sensor_msgs/PointCloud2` bags with `rosbags` (ROS 2 .db3, ROS 1 .bag),
the fields as ROS drivers publish them: x, y, z, intensity (float32) and t (uint32 ns after
the header stamp, as Ouster's driver)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

POINT_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"),
                        ("t", "<u4")])
FLOAT32, UINT32 = 7, 6


def pointcloud2(typestore, stamp_s: float, points, times_s=None, frame_id="lidar"):
    """One PointCloud2 message (a 1 x N unordered cloud)."""
    types = typestore.types
    pts = np.asarray(points, float).reshape(-1, 3)
    rec = np.zeros(len(pts), POINT_DTYPE)
    rec["x"], rec["y"], rec["z"] = pts.T
    if times_s is not None:
        rec["t"] = np.round((np.asarray(times_s, float) - stamp_s) * 1e9).clip(0, 2**32 - 1)
    sec = int(np.floor(stamp_s))
    header_type = types["std_msgs/msg/Header"]
    extra = {"seq": 0} if "seq" in header_type.__dataclass_fields__ else {}  # ROS 1
    header = header_type(
        stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((stamp_s - sec) * 1e9))),
        frame_id=frame_id, **extra)
    field = types["sensor_msgs/msg/PointField"]
    fields = [field(name=n, offset=POINT_DTYPE.fields[n][1], datatype=FLOAT32 if n != "t" else UINT32,
                    count=1) for n in POINT_DTYPE.names]
    return types["sensor_msgs/msg/PointCloud2"](
        header=header, height=1, width=len(pts), fields=fields, is_bigendian=False,
        point_step=POINT_DTYPE.itemsize, row_step=POINT_DTYPE.itemsize * len(pts),
        data=rec.view(np.uint8).copy(), is_dense=True)


def write_bag(path, sweeps, topic: str = "/points", ros: int = 2, frame_id: str = "lidar") -> Path:
    """Sweeps [(stamp s, points (N, 3), times s or None)] as a bag: ROS 2 (a folder with a
    .db3 and metadata.yaml) or ROS 1 (a .bag file)."""
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    msgtype = "sensor_msgs/msg/PointCloud2"
    if ros == 2:
        from rosbags.rosbag2 import Writer

        store = get_typestore(Stores.ROS2_HUMBLE)
        with Writer(path) as writer:
            conn = writer.add_connection(topic, msgtype, typestore=store)
            for stamp, pts, times in sweeps:
                msg = pointcloud2(store, stamp, pts, times, frame_id)
                writer.write(conn, int(stamp * 1e9), store.serialize_cdr(msg, msgtype))
    else:
        from rosbags.rosbag1 import Writer

        store = get_typestore(Stores.ROS1_NOETIC)
        with Writer(path) as writer:
            conn = writer.add_connection(topic, msgtype, typestore=store)
            for stamp, pts, times in sweeps:
                msg = pointcloud2(store, stamp, pts, times, frame_id)
                writer.write(conn, int(stamp * 1e9), store.serialize_ros1(msg, msgtype))
    return path
