"""Ouster sensors (`ouster:HOST`, `ouster-pcap:FILE`): not built yet (issue 20). ouster-sdk
1.0.1 installs and imports here; the reader and its round-trip test are still to write."""

from __future__ import annotations

from controller.errors import InputError


def open_ouster(cfg):
    raise InputError(f"lidar {cfg.name!r}: {cfg.source}: Ouster sources are not supported yet "
                     "(use velodyne, velodyne-pcap, rosbag or replay)")
