"""Latitude and longitude <-> north-east metres around an origin, as ArduPilot does it.

Flat earth around the origin, with ArduPilot's own radius (`RADIUS_OF_EARTH`, so its
LATLON_TO_M = 0.01113188 m per 1e-7 degree) and longitude scaled by the cosine of the
origin's latitude (`Location::get_distance_NE`): over a canal's few kilometres the error is
well under a metre, and both ends of a MAVLink link, and a log reader, agree exactly.
Works on floats and on numpy arrays.
"""

from __future__ import annotations

import numpy as np

EARTH_RADIUS_M = 6378100.0


def geodetic_to_ned(lat_deg, lon_deg, origin):
    """Latitude/longitude (degrees) -> (north, east) metres from `origin` = (lat, lon[, alt])."""
    lat0, lon0 = float(origin[0]), float(origin[1])
    dlon = (np.asarray(lon_deg, float) - lon0 + 180.0) % 360.0 - 180.0
    north = np.radians(np.asarray(lat_deg, float) - lat0) * EARTH_RADIUS_M
    east = np.radians(dlon) * EARTH_RADIUS_M * np.cos(np.radians(lat0))
    if np.ndim(north) == 0:
        return float(north), float(east)
    return north, east


def ned_to_geodetic(north, east, origin):
    """The inverse of `geodetic_to_ned`: (latitude, longitude) in degrees."""
    lat0, lon0 = float(origin[0]), float(origin[1])
    lat = lat0 + np.degrees(np.asarray(north, float) / EARTH_RADIUS_M)
    lon = lon0 + np.degrees(np.asarray(east, float) / (EARTH_RADIUS_M * np.cos(np.radians(lat0))))
    lon = (lon + 180.0) % 360.0 - 180.0
    if np.ndim(lat) == 0:
        return float(lat), float(lon)
    return lat, lon
