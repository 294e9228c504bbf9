"""Latitude/longitude to a local east/north frame (WGS84, tangent plane)."""
from __future__ import annotations

import numpy as np

_A = 6378137.0                  # WGS84 semi-major axis [m]
_E2 = 6.69437999014e-3          # first eccentricity squared


def _ecef(lat, lon):
    lat, lon = np.radians(lat), np.radians(lon)
    n = _A / np.sqrt(1.0 - _E2 * np.sin(lat) ** 2)
    return np.stack([n * np.cos(lat) * np.cos(lon), n * np.cos(lat) * np.sin(lon), n * (1 - _E2) * np.sin(lat)], -1)


def latlon_to_local(lat, lon, origin_lat: float, origin_lon: float):
    """East/north [m] of (lat, lon) [deg] in the tangent plane at the origin.

    Heights are taken as 0 (a ground robot's GPS height is not used). Shapes
    broadcast; returns (east, north) arrays. Error vs. a full geodesic stays
    below 1 mm over a few km.
    """
    d = _ecef(np.asarray(lat, float), np.asarray(lon, float)) - _ecef(origin_lat, origin_lon)
    la, lo = np.radians(origin_lat), np.radians(origin_lon)
    east = -np.sin(lo) * d[..., 0] + np.cos(lo) * d[..., 1]
    north = -np.sin(la) * np.cos(lo) * d[..., 0] - np.sin(la) * np.sin(lo) * d[..., 1] + np.cos(la) * d[..., 2]
    return east, north
