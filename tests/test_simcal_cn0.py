"""C/N0 against the error (gcs_tools.evaluate.simcal.cn0_vs_residual) on epochs with known answers, and its
tolerances against the reference they are centred on."""

from __future__ import annotations

import math

import numpy as np

from companion.gnss.geometry import ecef_to_ned_matrix, geodetic_to_ecef, sagnac_range_m
from companion.gnss.observations import make_epoch
from companion.gnss.systems import System
from gcs_tools.evaluate import simcal

LAT, LON = math.radians(52.5), math.radians(13.4)
P = geodetic_to_ecef(LAT, LON, 40.0)
CLOCK_M = 1234.5


def _epoch(t: float, el_deg: np.ndarray, error_m: np.ndarray, cn0: np.ndarray, system: System = System.GPS):
    """An epoch of satellites 20 000 km away at ``el_deg`` (azimuths spread), pseudorange = range + clock +
    ``error_m``: the residual at the truth is ``error_m`` less the median error above 40°."""
    az = np.radians(np.linspace(0.0, 330.0, len(el_deg)))
    el = np.radians(el_deg)
    ned = np.column_stack((np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)))
    sats = P + 2.0e7 * ned @ ecef_to_ned_matrix(LAT, LON)
    rho, _ = sagnac_range_m(sats, P)
    n = len(el_deg)
    return make_epoch(t, np.full(n, int(system)), np.arange(1, n + 1), rho + CLOCK_M + error_m,
                      sat_pos_ecef_m=sats, cn0_dbhz=cn0, elevation_deg=el_deg, corrected=True)


EL = np.array([60.0, 70.0, 80.0, 20.0, 25.0, 30.0])


def test_perfectly_separating_cn0_gives_auc_one_and_bin_medians():
    # three clean high satellites (clock exact), three reflected low ones: 20, 40, 60 m late and weak
    epochs = [_epoch(float(t), EL, np.array([0.0, 0.0, 0.0, 20.0, 40.0, 60.0]),
                     np.array([48.0, 47.0, 46.0, 28.0, 27.0, 26.0])) for t in range(5)]
    s = simcal.cn0_vs_residual(epochs, np.tile(P, (5, 1)))
    assert s["auc"]["all"]["auc"] == 1.0 and s["auc"]["GPS"]["auc"] == 1.0
    assert s["auc"]["all"]["bad"] == 15 and s["auc"]["all"]["n"] == 30
    bins = s["abs_residual_by_cn0"]
    assert abs(bins["<30"]["median"] - 40.0) < 1e-3 and bins["<30"]["n"] == 15
    assert abs(bins[">=45"]["median"]) < 1e-3 and bins[">=45"]["n"] == 15
    assert bins["30-35"]["n"] == 0 and math.isnan(bins["30-35"]["median"])
    assert s["bad_fraction_high_cn0"] == 0.0


def test_identical_cn0_tells_nothing_and_strong_reflections_count():
    epochs = [_epoch(float(t), EL, np.array([0.0, 0.0, 0.0, 20.0, 40.0, 60.0]), np.full(6, 42.0))
              for t in range(4)]
    s = simcal.cn0_vs_residual(epochs, np.tile(P, (4, 1)))
    assert s["auc"]["all"]["auc"] == 0.5  # ties count half
    assert s["bad_fraction_high_cn0"] == 0.5  # half of the strong signals are > 10 m off
    assert abs(s["abs_residual_by_cn0"]["40-45"]["median"] - 10.0) < 1e-3  # median of 0,0,0,20,40,60


def test_reference_sits_inside_every_cn0_tolerance_and_a_flat_pattern_fails():
    ref = simcal.SMARTLOC_REFERENCE
    assert all(r["pass"] for r in simcal.compare(ref, ref, simcal.CN0_TOLERANCES))
    bins = ref["cn0_vs_residual"]["abs_residual_by_cn0"]
    flat = {"cn0_vs_residual": {"auc": {k: {"auc": 0.5} for k in ("all", "GPS", "GLO")},
                                "abs_residual_by_cn0": {b: {"median": 100.0, "n": 1000} for b in bins},
                                "bad_fraction_high_cn0": 0.5}}
    rows = simcal.compare(ref, flat, simcal.CN0_TOLERANCES)
    assert not any(r["pass"] for r in rows)


def test_cn0_realism_is_a_valid_receiver_section_and_not_the_default():
    from companion.mission.scenarios import CN0_REALISM, RAW_RECEIVER
    from simvehicle.config import ReceiverConfig

    cfg = ReceiverConfig(enabled=True, **CN0_REALISM)
    cfg.validate()
    assert cfg.diffuse_fading and cfg.unmapped_spreading_ref_m > 0.0
    assert not ReceiverConfig(**RAW_RECEIVER).diffuse_fading  # the calibrated canyon stays as it was
