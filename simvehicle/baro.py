"""Barometer model: a MEMS pressure sensor's altitude (MS5611, BMP388 class), seeded, sampled with the IMU.

``pressure_alt = home_alt + h + datum + drift(t) + white``, with ``h`` the true height above home (−p_D),
``datum`` the pressure altitude's offset from the geometric one (the day's weather against the standard
atmosphere: drawn once, σ ``baro_datum_sigma_m``), ``drift`` a thermal ramp (its rate drawn once, σ
``baro_drift_m_s``) plus a random walk (``baro_walk_m_rt_s``), ``white`` σ ``baro_sigma_m`` per sample.
The absolute pressure is the standard atmosphere's at that pressure altitude (what the sensor measured,
read back the way PX4 reads it) and the temperature the standard atmosphere's at the true altitude plus
the electronics' self-heating (+10 °C). Its own random stream: the vehicle's other streams are unchanged.
"""

from __future__ import annotations

import math

import numpy as np

from simvehicle.config import ImuConfig
from simvehicle.noise import NormalBlocks

SELF_HEATING_C = 10.0


def standard_pressure_hpa(pressure_alt_m: np.ndarray) -> np.ndarray:
    """The standard atmosphere's pressure (hPa) at a pressure altitude (m; troposphere)."""
    return 1013.25 * (1.0 - 2.25577e-5 * np.asarray(pressure_alt_m, float)) ** 5.25588


class Barometer:
    def __init__(self, cfg: ImuConfig, rng: np.random.Generator, rate_hz: float, home_alt_m: float) -> None:
        self.cfg = cfg
        self._normals = NormalBlocks(rng)
        self._home_alt_m = home_alt_m
        self.datum_m = float(rng.normal(0.0, cfg.baro_datum_sigma_m)) if cfg.baro_datum_sigma_m else 0.0
        self.drift_rate_m_s = float(rng.normal(0.0, cfg.baro_drift_m_s)) if cfg.baro_drift_m_s else 0.0
        self._walk_step_m = cfg.baro_walk_m_rt_s * math.sqrt(1.0 / rate_hz)
        self._walk_m = 0.0

    def error_m(self, t_s: np.ndarray) -> np.ndarray:
        """The datum and the drift (no white noise) at ``t_s`` (n,), advancing the random walk by n
        samples."""
        n = len(t_s)
        walk = self._walk_m + np.cumsum(self._normals.take(n) * self._walk_step_m)
        self._walk_m = float(walk[-1]) if n else self._walk_m
        return self.datum_m + self.drift_rate_m_s * np.asarray(t_s, float) + walk

    def measure(self, t_s: np.ndarray, height_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(pressure altitude (m), absolute pressure (hPa), temperature (°C)), each (n,), at times ``t_s``
        (n,) of true heights above home ``height_m`` (n,)."""
        alt = self._home_alt_m + np.asarray(height_m, float)
        pa = alt + self.error_m(t_s) + self.cfg.baro_sigma_m * self._normals.take(len(t_s))
        temp = 15.0 - 0.0065 * alt + SELF_HEATING_C
        return pa, standard_pressure_hpa(pa), temp
