"""What one LiDAR sensor hands the merge: a complete sweep with its times, in its own frame."""

from __future__ import annotations

import importlib
import socket
from dataclasses import dataclass

import numpy as np

from controller.errors import InputError

EXTRA_HINT = "pip install 'canalnav[lidar]'"


@dataclass
class SensorScan:
    """One complete sweep of one sensor.

    `points` (N, 3) in the sensor's own frame; `times_s` (N,) each point's time on the
    bridge's clock (seconds since the run started), or None when the format has none;
    `stamp_s` the sweep's reference time on that clock (its end, or its message stamp).
    """

    points: np.ndarray
    times_s: np.ndarray | None
    stamp_s: float


def require(module: str, what: str):
    """Import an optional LiDAR library, or say which extra installs it (InputError)."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(f"{what} needs the Python package {module.split('.')[0]!r}, which is "
                         f"not installed: {EXTRA_HINT}") from None


def finite_rows(points: np.ndarray, times: np.ndarray | None = None):
    """Drop rows with a NaN/inf coordinate and the all-zero rows of "no return"."""
    pts = np.asarray(points, float).reshape(-1, 3)
    keep = np.isfinite(pts).all(axis=1) & (np.abs(pts).sum(axis=1) > 0)
    return pts[keep], (None if times is None else np.asarray(times, float)[keep])


def udp_listener(spec: str, host: str, port: int) -> socket.socket:
    """A non-blocking UDP socket bound to (host, port) with a large receive buffer, for a
    live sensor's packets; a port that cannot be had is an InputError naming the source."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        sock.bind((host, int(port)))
    except OSError as exc:
        sock.close()
        raise InputError(f"{spec}: cannot listen on UDP {host}:{port} ({exc})") from None
    sock.setblocking(False)
    return sock
