"""A single-point solution as the estimator's ``GnssFix`` (validity-stamped, honest accuracy)."""

from __future__ import annotations

import math

import numpy as np

from companion.domain.samples import GnssFix
from companion.gnss.geometry import ecef_to_geodetic, ecef_to_ned_matrix
from companion.gnss.spp import SppSolution

FIX_3D = 3


def to_fix(solution: SppSolution, t_validity_us: int) -> GnssFix | None:
    """The solution as a 3-D fix valid at ``t_validity_us`` (boot time); None without a solution.

    ``alt_m`` is the WGS-84 ellipsoidal height (no geoid model here: a log's MSL altitudes differ by
    the geoid undulation, tens of metres, which only a vertical alignment removes). ``h_acc_m`` /
    ``v_acc_m`` are the solution's 1-σ per horizontal axis / vertical, ``hdop`` its HDOP and
    ``v_ned_m_s`` the Doppler velocity when there was one."""
    if not solution.ok:
        return None
    lat, lon, h = (float(v) for v in ecef_to_geodetic(solution.p_ecef_m))
    v_ned = None
    if np.isfinite(solution.v_ecef_m_s).all():
        v_ned = ecef_to_ned_matrix(lat, lon) @ solution.v_ecef_m_s
    return GnssFix(
        int(t_validity_us),
        math.degrees(lat),
        math.degrees(lon),
        h,
        FIX_3D,
        solution.n_used,
        solution.h_acc_m,
        solution.v_acc_m,
        solution.dops.hdop,
        v_ned,
        solution.vel_acc_m_s,
    )
