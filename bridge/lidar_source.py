"""The bridge's LiDAR sources now live in `bridge.lidar`; these names stay for old imports."""

from bridge.lidar import (SCAN_SUFFIXES, LidarSource, ReplayLidarSource,  # noqa: F401
                          SimLidarSource, make_lidar_source, mount_transform,
                          parse_lidar_option, read_scan, segments)
