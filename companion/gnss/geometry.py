"""Receiver–satellite geometry in ECEF (WGS-84), vectorised over satellites.

The Earth rotates while a signal flies (~70 ms): a satellite position computed in the ECEF frame
of its transmission time must be rotated into the frame of the reception time. The first-order
form (Sagnac term, RTKLIB ``geodist``) is ``ρ = |r_s − r_r| + ω_e (x_s y_r − y_s x_r) / c``,
≈ 30 m at mid latitudes: leaving it out biases a single-point solution by tens of metres east.
"""

from __future__ import annotations

import numpy as np

from companion.gnss.constants import C_M_S, OMEGA_E_RAD_S, WGS84_A_M, WGS84_E2


def ecef_to_geodetic(p_ecef_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(…, 3) ECEF -> latitude (rad), longitude (rad), ellipsoidal height (m); 5 fixed-point
    iterations (< 0.1 mm at the surface and in orbit)."""
    p = np.asarray(p_ecef_m, dtype=float)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    r2 = x * x + y * y
    r = np.sqrt(r2)
    lat = np.arctan2(z, r * (1.0 - WGS84_E2))
    for _ in range(5):
        s = np.sin(lat)
        n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * s * s)
        lat = np.arctan2(z + WGS84_E2 * n * s, r)
    s = np.sin(lat)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * s * s)
    c = np.cos(lat)
    h = np.where(np.abs(c) > 1e-9, r / np.where(c == 0, 1.0, c) - n, np.abs(z) - n * (1.0 - WGS84_E2))
    return lat, np.arctan2(y, x), h


def geodetic_to_ecef(
    lat_rad: np.ndarray | float, lon_rad: np.ndarray | float, h_m: np.ndarray | float
) -> np.ndarray:
    s, c = np.sin(lat_rad), np.cos(lat_rad)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * s * s)
    return np.stack(
        [(n + h_m) * c * np.cos(lon_rad), (n + h_m) * c * np.sin(lon_rad), (n * (1.0 - WGS84_E2) + h_m) * s],
        axis=-1,
    )


def ecef_to_enu_matrix(lat_rad: float, lon_rad: float) -> np.ndarray:
    """(3, 3) rotation R with ``d_enu = R @ d_ecef`` at (lat, lon)."""
    sl, cl = np.sin(lat_rad), np.cos(lat_rad)
    so, co = np.sin(lon_rad), np.cos(lon_rad)
    return np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])


def ecef_to_ned_matrix(lat_rad: float, lon_rad: float) -> np.ndarray:
    """(3, 3) rotation R with ``d_ned = R @ d_ecef``."""
    enu = ecef_to_enu_matrix(lat_rad, lon_rad)
    return np.array([enu[1], enu[0], -enu[2]])


def sagnac_range_m(
    sat_ecef_m: np.ndarray, rx_ecef_m: np.ndarray, earth_rotation: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Geometric ranges (n,) and unit line-of-sight vectors receiver→satellite (n, 3).

    ``sat_ecef_m`` (n, 3) are the positions at transmission in the transmission-time ECEF frame;
    ``earth_rotation`` adds the Sagnac term (False only to show what leaving it out costs)."""
    d = sat_ecef_m - rx_ecef_m
    r = np.sqrt(np.einsum("ij,ij->i", d, d))
    los = d / r[:, None]
    if earth_rotation:
        r = r + OMEGA_E_RAD_S * (sat_ecef_m[:, 0] * rx_ecef_m[1] - sat_ecef_m[:, 1] * rx_ecef_m[0]) / C_M_S
    return r, los


def azimuth_elevation_rad(
    los_ecef: np.ndarray, lat_rad: float, lon_rad: float
) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth (rad, from north, clockwise) and elevation (rad) of unit vectors (n, 3) at a site."""
    enu = los_ecef @ ecef_to_enu_matrix(lat_rad, lon_rad).T
    el = np.arcsin(np.clip(enu[:, 2], -1.0, 1.0))
    az = np.arctan2(enu[:, 0], enu[:, 1]) % (2 * np.pi)
    return az, el
