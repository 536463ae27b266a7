"""Real GLONASS and BeiDou observations and navigation records of one receiver solved to its position.

``tests/data/real_glo_bds`` (provenance and licence in ``tests/data/README.md``): excerpts of the
static base files of MatRTKLIB's examples, 2024-06-24 08:20-08:25 GPST, Nagoya: a Septentrio mosaic-X5
(sbf2rin 15.9.0, RINEX 3.04) tracking GPS, GLONASS (FDMA G1, 9 slots), BeiDou (B1I, B3I; 25 satellites:
7 geostationary, 9 inclined-geosynchronous, 9 medium orbits), Galileo and QZSS, and its own mixed
navigation file, of which the GPS, GLONASS and BeiDou records are kept. What the files check that the
2021 ones (``test_rinex_real.py``) cannot: GLONASS epochs of ephemeris in UTC (Moscow time less 3 h,
GPS time less the 18 leap seconds), the PZ-90 state vectors integrated to the epoch, each slot's
frequency channel (Doppler); BeiDou time (GPS time − 14 s), the geostationary satellites' own orbit
transformation, the B1I frequency; and the rejection counters on a file with an unhealthy GLONASS slot
(R02), Galileo and QZSS observations without records, and a BeiDou line with only a B3I code.
"""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

import companion.gnss.ephemeris as ephemeris_module
from companion.gnss.ephemeris import EphemerisStore, attach_broadcast
from companion.gnss.geometry import geodetic_to_ecef
from companion.gnss.spp import SppConfig, solve_position
from companion.gnss.systems import System, is_beidou_geo
from companion.gnss.timescale import gps_from_calendar
from gcs_tools.gnss import rinex
from gcs_tools.gnss.sources import rinex_input
from tests.rinex_real_helpers import enu_errors, residuals_at, row

DATA = Path(__file__).parent / "data" / "real_glo_bds"
OBS = DATA / "base_excerpt.obs"
NAV = DATA / "base_excerpt.nav"
# the base antenna's position as MatRTKLIB's example gives it (examples/data/static/base_position.txt:
# latitude, longitude in degrees, ellipsoidal height; how it was surveyed is not stated); the header's
# APPROX POSITION XYZ (the receiver's own) is 0.4 m from it
BASE_ECEF_M = geodetic_to_ecef(math.radians(35.134707705), math.radians(136.977577939), 104.853)

G, R, C, E, J = System.GPS, System.GLONASS, System.BEIDOU, System.GALILEO, System.QZSS
C_M_S = 299792458.0
# the observation header's GLONASS SLOT / FRQ # line
HEADER_CHANNELS = {1: 1, 2: -4, 3: 5, 11: 0, 12: -1, 13: -2, 17: 4, 18: -3, 24: 2}
# what the base file refuses and the store drops: C05's B3I-only line at 08:25 (obs_no_pseudorange),
# R02's two records and R10's one (health 1), and per epoch 9 Galileo, 2 QZSS (no records kept) and
# R02 (its records unhealthy): 3 × 12 without an ephemeris
REJECTED = Counter({"obs_no_pseudorange": 1, "nav_unhealthy": 3, "no_ephemeris": 36})


def _t(*hms: float) -> float:
    return gps_from_calendar(2024, 6, 24, int(hms[0]), int(hms[1]), float(hms[2]), "GPS")


def _counts(epoch) -> tuple[int, ...]:
    return tuple(int((epoch.system == s).sum()) for s in (G, R, C, E, J))


@pytest.fixture(scope="module")
def base():
    return rinex_input(OBS, [NAV])


# --- the reader, against the printed files ----------------------------------------------------------


def test_observation_file_reads_every_epoch_and_its_printed_values():
    """sbf2rin 15.9.0: a receiver-channel column (``X1``) first in every system's types, GLONASS on
    C1C with its Doppler read at the G1 centre frequency (the channel comes with the navigation data),
    BeiDou on C2I (B1I) with the B1I wavelength, C23-C60's empty B2I fields, C05 at 08:25 with only a
    B3I code (refused, counted)."""
    obs = rinex.read_obs(OBS)
    assert obs.version == 3.04 and obs.time_system == "GPS"
    assert obs.rejected == Counter({"no_pseudorange": 1})
    assert [e.t_gps_s for e in obs.epochs] == [_t(8, 20, 0), _t(8, 22, 30), _t(8, 25, 0)]
    assert [_counts(e) for e in obs.epochs] == [(12, 9, 25, 9, 2), (12, 9, 25, 9, 2), (11, 9, 24, 9, 2)]
    assert 5 not in obs.epochs[2].prn[obs.epochs[2].system == C]
    np.testing.assert_allclose(obs.approx_position_ecef_m, [-3817680.7270, 3562839.5216, 3650159.2407])
    first, mid, last = obs.epochs
    for epoch, system, prn, pr, dop, cn0, f_hz in [
        (first, R, 3, 22571036.226, 2457.090, 43.250, 1602.0e6),  # G1 centre until the channel is known
        (first, C, 59, 36907864.314, 333.641, 45.281, 1561.098e6),  # a BDS-3 geostationary satellite
        (mid, C, 23, 24416124.258, 3022.517, 43.656, 1561.098e6),  # B1I and B3I, no B2I
        (last, G, 24, 23327242.357, 4201.133, 39.844, 1575.42e6),
        (last, R, 24, 21930086.003, -3828.702, 44.250, 1602.0e6),
    ]:
        i = row(epoch, system, prn)
        assert epoch.pseudorange_m[i] == pr and epoch.cn0_dbhz[i] == cn0
        assert epoch.pseudorange_rate_m_s[i] == pytest.approx(-dop * C_M_S / f_hz, rel=1e-12)


def test_navigation_file_glonass_state_vectors_and_beidou_records():
    """GLONASS records: epochs in UTC (GPS time = UTC + 18 s), state vectors in km, km/s, km/s² read
    in m, the frequency channel of each slot as the observation header prints it, R02's health flag;
    BeiDou records: toe and toc in BDT (GPS time = BDT + 14 s, BDT week 964 = GPS week 2320)."""
    nav = rinex.read_nav(NAV)
    assert nav.rejected == Counter() and nav.leap_seconds == 18
    assert Counter(System(e.system) for e in nav.kepler) == Counter({G: 13, C: 25})
    assert len(nav.glonass) == 19  # 10 slots at 08:15 UTC, 9 again at 08:45
    np.testing.assert_array_equal(nav.klobuchar[0], [1.8626e-08, 2.2352e-08, -1.1921e-07, -5.9605e-08])
    r01 = next(g for g in nav.glonass if g.prn == 1 and g.toe_gps_s == _t(8, 15, 18))
    assert r01.pos_ecef_m == (-13736887.69531, -3309238.28125, 21242412.59766)
    assert r01.vel_ecef_m_s == pytest.approx((-1554.378509521, -2458.472251892, -1386.62815094), rel=1e-15)
    assert r01.acc_ecef_m_s2 == pytest.approx((9.313225746155e-07, 1.862645149231e-06, -1.862645149231e-06))
    assert r01.clock_bias_s == 8.934084326029e-05 and r01.gamma_n == 9.094947017729e-13
    assert {g.prn: g.channel for g in nav.glonass if g.prn in HEADER_CHANNELS} == HEADER_CHANNELS
    assert sorted(g.prn for g in nav.glonass if g.health) == [2, 2, 10]
    c01 = next(e for e in nav.kepler if e.system == C and e.prn == 1)
    assert c01.toe_gps_s == c01.toc_gps_s == _t(8, 0, 14) == 2320 * 604800.0 + 115200.0 + 14.0
    assert c01.af0_s == 9.039411088452e-04 and c01.sqrt_a_m05 == 6.493358730316e03
    assert c01.tgd_s == -4.9e-09  # TGD1 (B1I)
    g06 = next(e for e in nav.kepler if e.system == G and e.prn == 6)
    assert g06.toe_gps_s == _t(8, 0, 0)


# --- single-point solutions against the base position -----------------------------------------------

# (systems, horizontal m, |vertical| m): measured maxima over the 3 epochs 3.0/1.7 (all), 3.4/2.7 (GPS),
# 2.9/4.4 (GLONASS: 7 slots above 5°), 2.5/1.8 (BeiDou: 21), 3.4/3.9 (GPS + GLONASS), 2.7/0.5 (GPS + BeiDou);
# every solution 2.4-3.3 m north of the reference, whichever constellation (the reference's datum or
# the ionosphere model, not a time base). Time bases off by a second already move them 100 m-1 km.
TOLERANCES = [
    ((G, R, C), 4.0, 4.0),
    ((G,), 5.0, 5.0),
    ((R,), 5.0, 7.0),
    ((C,), 4.0, 4.0),
    ((G, R), 5.0, 6.0),
    ((G, C), 4.0, 4.0),
]


@pytest.mark.parametrize(
    ("systems", "h_tol_m", "v_tol_m"),
    TOLERANCES,
    ids=["all", "gps", "glonass", "beidou", "gps+glo", "gps+bds"],
)
def test_base_solutions_per_constellation(base, systems, h_tol_m, v_tol_m):
    """GLONASS alone (its UTC epochs, state vectors, own clock) and BeiDou alone (BDT, geostationary
    orbits) land on the base like GPS does; all three epochs."""
    assert base.rejected == REJECTED
    enu = enu_errors(base.epochs, base.klobuchar, systems, BASE_ECEF_M)
    assert len(enu) == 3
    assert np.hypot(enu[:, 0], enu[:, 1]).max() < h_tol_m
    assert np.abs(enu[:, 2]).max() < v_tol_m


def _shifted_store(nav, glonass_s: float = 0.0, beidou_s: float = 0.0) -> EphemerisStore:
    """The store a reader would build that put the GLONASS or BeiDou records' times off by so much."""
    kepler = [dataclasses.replace(e, toe_gps_s=e.toe_gps_s + beidou_s, toc_gps_s=e.toc_gps_s + beidou_s)
              if e.system == C else e for e in nav.kepler]
    glonass = [dataclasses.replace(g, toe_gps_s=g.toe_gps_s + glonass_s) for g in nav.glonass]
    return EphemerisStore(kepler, glonass, nav.klobuchar)


def _attached(store: EphemerisStore, rejected: Counter | None = None) -> list:
    out = []
    for e in rinex.read_obs(OBS).epochs:
        e = rinex.fix_glonass_rates(e, store.glonass_channel(e.prn))
        out.append(attach_broadcast(e, store, rejected)[0])
    return out


def test_the_tolerances_catch_wrong_glonass_and_beidou_time_bases():
    """The mistakes the known answer is there for, each far beyond every tolerance above: GLONASS
    records read as GPS time (leap seconds not added: measured 13-18 km alone, 3.8-5.2 km with GPS),
    GLONASS Moscow time not taken off (3 h: no record within 30 min, no GLONASS solution), BeiDou
    time read as GPS time (14 s: measured 1.5-2.2 km alone, 0.9-1.3 km with GPS)."""
    nav = rinex.read_nav(NAV)
    leap = _attached(_shifted_store(nav, glonass_s=-18.0))
    assert np.linalg.norm(enu_errors(leap, nav.klobuchar, (R,), BASE_ECEF_M), axis=1).min() > 10_000.0
    assert np.linalg.norm(enu_errors(leap, nav.klobuchar, (G, R), BASE_ECEF_M), axis=1).min() > 3_000.0
    rejected: Counter[str] = Counter()
    moscow = _attached(_shifted_store(nav, glonass_s=3 * 3600.0), rejected)
    assert rejected["no_ephemeris"] == 36 + 3 * 8  # the 8 healthy slots lose theirs too
    assert all(not solve_position(e.select(e.system == R)).ok for e in moscow)
    bdt = _attached(_shifted_store(nav, beidou_s=-14.0))
    assert np.linalg.norm(enu_errors(bdt, nav.klobuchar, (C,), BASE_ECEF_M), axis=1).min() > 1_000.0
    assert np.linalg.norm(enu_errors(bdt, nav.klobuchar, (G, C), BASE_ECEF_M), axis=1).min() > 500.0


def test_glonass_records_integrate_to_the_epoch_from_either_set():
    """Of the two GLONASS sets (08:15 and 08:45 UTC), the store takes the nearest, 08:15, at every
    epoch (5-10 min of integration); the 08:45 set alone, integrated back 20-25 min, still lands within
    the GLONASS tolerances (measured 2.1-2.6 m horizontal, 4.5-5.3 m vertical)."""
    nav = rinex.read_nav(NAV)
    early = [g for g in nav.glonass if g.toe_gps_s == _t(8, 15, 18)]
    late = [g for g in nav.glonass if g.toe_gps_s == _t(8, 45, 18)]
    assert len(early) == 10 and len(late) == 9
    both = _attached(EphemerisStore(nav.kepler, nav.glonass, nav.klobuchar))
    first = _attached(EphemerisStore(nav.kepler, early, nav.klobuchar))
    for a, b in zip(both, first, strict=True):
        np.testing.assert_array_equal(a.sat_pos_ecef_m, b.sat_pos_ecef_m)
    late_only = _attached(EphemerisStore(nav.kepler, late, nav.klobuchar))
    enu = enu_errors(late_only, nav.klobuchar, (R,), BASE_ECEF_M)
    assert np.hypot(enu[:, 0], enu[:, 1]).max() < 5.0 and np.abs(enu[:, 2]).max() < 7.0


def test_beidou_geostationary_satellites_fit_and_need_their_transformation(base, monkeypatch):
    """The 6 geostationary satellites above the mask (C01-C04, C59, C60; C05 is at 1° over the
    Indian Ocean) are used with residuals of a few metres (measured ≤ 3.2 m); computed as medium-orbit
    satellites (no −5° rotation, Earth rotation in the node rate) the BeiDou solution is 200 km off."""
    for e in base.epochs:
        sel = e.select(e.system == C)
        sol = solve_position(sel, SppConfig(), klobuchar=base.klobuchar)
        geo = is_beidou_geo(sel.prn) & sol.used
        assert sorted(sel.prn[geo]) == [1, 2, 3, 4, 59, 60] and not sol.excluded.any()
        assert np.abs(sol.residuals_m[geo]).max() < 5.0
    monkeypatch.setattr(ephemeris_module, "is_beidou_geo", lambda prn: np.zeros(np.shape(prn), dtype=bool))
    nav = rinex.read_nav(NAV)
    as_meo = _attached(EphemerisStore(nav.kepler, nav.glonass, nav.klobuchar))
    assert np.linalg.norm(enu_errors(as_meo, nav.klobuchar, (C,), BASE_ECEF_M), axis=1).min() > 100_000.0


def test_glonass_doppler_needs_each_slots_channel(base):
    """Doppler velocity of the static antenna from GLONASS alone: below 0.03 m/s (measured) with
    each slot's frequency (channels −4..+5); read at the G1 centre frequency instead, 0.14-0.29 m/s."""
    for e in base.epochs:
        sol = solve_position(e.select(e.system == R), klobuchar=base.klobuchar)
        assert np.linalg.norm(sol.v_ecef_m_s) < 0.06
    nav = rinex.read_nav(NAV)
    store = EphemerisStore(nav.kepler, nav.glonass, nav.klobuchar)
    for e in rinex.read_obs(OBS).epochs:  # no fix_glonass_rates: every slot at channel 0
        e = attach_broadcast(e, store)[0]
        sol = solve_position(e.select(e.system == R), klobuchar=nav.klobuchar)
        assert np.linalg.norm(sol.v_ecef_m_s) > 0.1


def _cli(tmp_path: Path, letters: str) -> dict:
    truth = ",".join(f"{x:.3f}" for x in BASE_ECEF_M)
    r = subprocess.run(
        [sys.executable, "-m", "gcs_tools", "gnss", "spp", str(OBS), "--nav", str(NAV),
         f"--truth-ecef={truth}", "--systems", letters, "--out", str(tmp_path / "spp")],
        capture_output=True, text=True, timeout=120,
    )
    assert r.returncode == 0, r.stderr
    return json.loads((tmp_path / "spp" / "summary.json").read_text())


@pytest.mark.parametrize(
    ("letters", "h_tol_m", "v_tol_m", "not_selected"),
    [("R", 5.0, 7.0, 109), ("C", 4.0, 4.0, 59)],
    ids=["glonass", "beidou"],
)
def test_gnss_spp_cli_on_the_base(tmp_path, letters, h_tol_m, v_tol_m, not_selected):
    """``beliefnav gnss spp --systems R`` / ``C``: the same answers through the command; the other
    observations counted (169 read, 36 without an ephemeris, 24 GLONASS or 74 BeiDou used)."""
    summary = _cli(tmp_path, letters)
    assert summary["epochs"] == 3 and summary["solutions"] == 3
    assert summary["rejected"] == {**REJECTED, "system_not_selected": not_selected}
    assert summary["errors"]["horizontal_m"]["p95"] < h_tol_m
    assert summary["errors"]["vertical_abs_m"]["p95"] < v_tol_m


def test_epoch_residuals_at_truth_of_raw_pseudoranges_leave_the_atmosphere_out(base):
    """The per-satellite residuals at the truth with the modelled atmosphere taken off: above the
    solution's 5° mask every one within a few metres (measured at most 6.5 m) and each system's median
    near zero (GPS −0.05, BeiDou +0.29, GLONASS −2.46 m: its channels' biases; below 30° GPS −0.07, BeiDou
    +1.93 m). Before, with the atmosphere kept: up to 28.8 m, GPS +4.67, BeiDou +4.38 m, below 30° +11.7
    and +11.1 m. Below the mask, within 3° of the horizon, the troposphere model itself fails (1/sin el:
    120-300 m) and is not checked."""
    r, el, system = residuals_at(base.epochs, base.klobuchar, BASE_ECEF_M)
    above = el > SppConfig().elevation_mask_deg
    assert above.sum() == 114 and np.abs(r[above]).max() < 8.0
    for s, tol in ((G, 1.0), (C, 1.0), (R, 3.0)):
        assert abs(np.median(r[above & (system == s)])) < tol
    for s in (G, C):
        assert abs(np.median(r[above & (system == s) & (el < 30.0)])) < 3.0
