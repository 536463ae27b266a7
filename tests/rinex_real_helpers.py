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


def residuals_at(epochs, klobuchar, p_ecef_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every observation's residual at ``p_ecef_m`` (``baseline.epoch_residuals_at_truth`` with the
    solution's atmosphere models), its elevation (degrees) and its system, over all ``epochs``."""
    from gcs_tools.gnss.baseline import epoch_residuals_at_truth

    at = [epoch_residuals_at_truth(e, p_ecef_m, SppConfig(), klobuchar) for e in epochs]
    return (np.concatenate([a.residual_m for a in at]), np.concatenate([a.elevation_deg for a in at]),
            np.concatenate([e.system for e in epochs]))
