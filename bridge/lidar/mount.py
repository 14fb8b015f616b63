"""Where a sensor sits on the boat: sensor-to-body transforms (x forward, y starboard, z down)."""

from __future__ import annotations

import numpy as np

from scenarios.sensors.lidar import sensor_rotation


def mount_transform(mount) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) from sensor to body frame for a mount (x, y, z m, roll, pitch, yaw rad):
    p_body = R p_sensor + t, R = Rz(yaw) Ry(pitch) Rx(roll) as `scenarios.sensors.lidar.LidarMount`.
    A sensor that reports x forward, y left, z up (ROS, Velodyne, Ouster) has roll = 180 deg."""
    x, y, z, roll, pitch, yaw = (float(v) for v in mount)
    return sensor_rotation(roll, pitch, yaw), np.array([x, y, z])


def to_body(points: np.ndarray, mount) -> np.ndarray:
    """Sensor-frame points (N, 3) into the body frame."""
    rotation, offset = mount_transform(mount)
    return np.asarray(points, float) @ rotation.T + offset
