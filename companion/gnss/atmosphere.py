"""Broadcast ionosphere (Klobuchar) and standard-atmosphere troposphere (Saastamoinen) delays.

Both return the delay in metres on the signal's own frequency, vectorised over satellites. They
are applied to raw pseudoranges (RINEX, UBX); smartLoc's pseudoranges are already corrected.
"""

from __future__ import annotations

import numpy as np

from companion.gnss.constants import C_M_S, DFREQ_G1_HZ, FREQ_B1I_HZ, FREQ_G1_HZ, FREQ_L1_HZ
from companion.gnss.systems import System

REL_HUMIDITY = 0.7  # Saastamoinen with the standard atmosphere (RTKLIB's default)


def klobuchar_m(
    alpha: np.ndarray,
    beta: np.ndarray,
    lat_rad: float,
    lon_rad: float,
    az_rad: np.ndarray,
    el_rad: np.ndarray,
    tow_s: float,
) -> np.ndarray:
    """GPS L1 ionospheric delay (m), IS-GPS-200 20.3.3.5.2.5; ``tow_s`` GPS seconds of week."""
    el = el_rad / np.pi  # semicircles
    psi = 0.0137 / (el + 0.11) - 0.022
    phi = np.clip(lat_rad / np.pi + psi * np.cos(az_rad), -0.416, 0.416)
    lam = lon_rad / np.pi + psi * np.sin(az_rad) / np.cos(phi * np.pi)
    phim = phi + 0.064 * np.cos((lam - 1.617) * np.pi)
    t = (43200.0 * lam + tow_s) % 86400.0
    f = 1.0 + 16.0 * (0.53 - el) ** 3
    amp = np.maximum(np.polyval(np.asarray(alpha)[::-1], phim), 0.0)
    per = np.maximum(np.polyval(np.asarray(beta)[::-1], phim), 72000.0)
    x = 2.0 * np.pi * (t - 50400.0) / per
    delay_s = f * np.where(np.abs(x) < 1.57, 5e-9 + amp * (1.0 - x * x / 2.0 + x**4 / 24.0), 5e-9)
    return C_M_S * delay_s


def iono_frequency_scale(system: np.ndarray, glonass_channel: np.ndarray | None = None) -> np.ndarray:
    """(f_L1 / f)² per observation: the L1 delay scaled to B1I / G1 (1.0 for L1/E1 signals)."""
    system = np.asarray(system)
    f = np.full(system.shape, FREQ_L1_HZ)
    f = np.where(system == System.BEIDOU, FREQ_B1I_HZ, f)
    ch = np.zeros(system.shape) if glonass_channel is None else np.asarray(glonass_channel, dtype=float)
    f = np.where(system == System.GLONASS, FREQ_G1_HZ + ch * DFREQ_G1_HZ, f)
    return (FREQ_L1_HZ / f) ** 2


def saastamoinen_m(
    lat_rad: float, h_m: float, el_rad: np.ndarray, humidity: float = REL_HUMIDITY
) -> np.ndarray:
    """Tropospheric delay (m) with the standard atmosphere (Saastamoinen 1972; RTKLIB tropmodel);
    0 below the horizon or outside −100 m … 10 km of height."""
    el_rad = np.asarray(el_rad, dtype=float)
    if not (-100.0 <= h_m <= 1e4):
        return np.zeros(el_rad.shape)
    hgt = max(h_m, 0.0)
    pres = 1013.25 * (1.0 - 2.2557e-5 * hgt) ** 5.2568
    temp = 15.0 - 6.5e-3 * hgt + 273.16
    e = 6.108 * humidity * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    cosz = np.cos(np.pi / 2 - np.maximum(el_rad, 1e-3))
    trph = 0.0022768 * pres / (1.0 - 0.00266 * np.cos(2.0 * lat_rad) - 0.00028 * hgt / 1e3) / cosz
    trpw = 0.002277 * (1255.0 / temp + 0.05) * e / cosz
    return np.where(el_rad > 0, trph + trpw, 0.0)
