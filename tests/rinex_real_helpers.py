"""Helpers of the known-answer tests on real RINEX files (``test_rinex_real*.py``)."""

from __future__ import annotations

import numpy as np

from companion.gnss.geometry import ecef_to_enu_matrix, ecef_to_geodetic
from companion.gnss.spp import SppConfig, solve_position
from companion.gnss.systems import System


def row(epoch, system: System, prn: int) -> int:
    """The epoch's row of one satellite (exactly one)."""
    (i,) = np.flatnonzero((epoch.system == system) & (epoch.prn == prn))
    return int(i)


def enu_errors(epochs, klobuchar, systems, ref, config: SppConfig | None = None) -> np.ndarray:
    """East, north, up (m) of each epoch's single-point solution from ``systems`` only, less ``ref``."""
    lat, lon, _ = ecef_to_geodetic(ref)
    rot = ecef_to_enu_matrix(float(lat), float(lon))
    out = []
    for e in epochs:
        sol = solve_position(e.select(np.isin(e.system, systems)), config or SppConfig(), klobuchar=klobuchar)
        assert sol.ok, sol.reason
        out.append(rot @ (sol.p_ecef_m - ref))
    return np.array(out)
