"""A ground vehicle's yaw rate from a strapdown IMU mounted any way up (pure numpy).

Some drives give an IMU instead of wheel odometry (the UrbanNav data set as TU Chemnitz formats it:
``imu`` rows of specific force and body rate in the sensor's own axes, mounting not stated). A car's
heading turns about the local vertical, so its yaw rate is the body rate projected on "up":

* **up** in sensor axes: the mean specific force over the drive (a car's accelerations average out
  over minutes; gravity does not), whatever the sensor's axis convention (z up or down);
* **bias**: a car's yaw-rate sensor is zeroed at standstill; so is this one, on every second in which
  the IMU is still (specific-force magnitude spread < ``STILL_ACC_M_S2``, every rate <
  ``STILL_RATE_RAD_S``); with no still second the bias stays (the filter's yaw-rate bias state takes it);
* **rate**: the mean over ``bin_s`` bins (the integral of the rate, which is what the heading needs,
  is kept exactly up to the bins' edges), stamped at the bins' centres.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

STILL_WINDOW_S = 1.0
STILL_ACC_M_S2 = 0.05  # σ of the specific force's magnitude within a still second (noise, idling engine)
STILL_RATE_RAD_S = 0.01  # σ and |mean| of the rate about up within a still second (0.6°/s: above a MEMS bias)


class YawRate(NamedTuple):
    t_s: np.ndarray  # (k,) bin centres
    yaw_rate_ccw_rad_s: np.ndarray  # (k,) counter-clockwise seen from above (about up), bias removed
    up_sensor: np.ndarray  # (3,) unit vector "up" in the sensor's axes
    bias_rad_s: float  # removed (0.0 when no still second was found)
    still_s: float  # seconds of standstill the bias came from


def _bins(t_s: np.ndarray, width_s: float) -> np.ndarray:
    """Start indices of consecutive ``width_s`` bins of time-ordered stamps, and the end."""
    b = np.floor((t_s - t_s[0]) / width_s).astype(np.int64)
    return np.r_[0, np.nonzero(np.diff(b))[0] + 1, len(b)]


def _means(v: np.ndarray, edges: np.ndarray) -> np.ndarray:
    return np.add.reduceat(v, edges[:-1], axis=0) / np.diff(edges).reshape((-1,) + (1,) * (v.ndim - 1))


def yaw_rate_from_imu(t_s: np.ndarray, f_sensor_m_s2: np.ndarray, w_sensor_rad_s: np.ndarray,
                      bin_s: float = 0.1) -> YawRate:
    """The yaw rate about up from time-ordered IMU samples (t (n,), specific force (n, 3), rate (n, 3))."""
    mean_f = f_sensor_m_s2.mean(axis=0)
    up = mean_f / np.linalg.norm(mean_f)
    w_up = w_sensor_rad_s @ up
    f_norm = np.linalg.norm(f_sensor_m_s2, axis=1)
    win = _bins(t_s, STILL_WINDOW_S)
    n_win = np.diff(win)
    f_sd = np.sqrt(np.maximum(_means(f_norm**2, win) - _means(f_norm, win) ** 2, 0.0))
    w_mean = _means(w_up, win)
    w_sd = np.sqrt(np.maximum(_means(w_up**2, win) - w_mean**2, 0.0))
    quiet = (f_sd < STILL_ACC_M_S2) & (w_sd < STILL_RATE_RAD_S)
    still = (n_win >= 2) & quiet & (np.abs(w_mean) < STILL_RATE_RAD_S)
    bias = float(np.sum(w_mean[still] * n_win[still]) / np.sum(n_win[still])) if still.any() else 0.0
    edges = _bins(t_s, bin_s)
    still_s = float(still.sum()) * STILL_WINDOW_S
    return YawRate(_means(t_s, edges), _means(w_up, edges) - bias, up, bias, still_s)
