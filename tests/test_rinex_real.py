"""Real RINEX 3.04 files from two receivers of one day solved to a known position.

``tests/data/real_rinex3`` (provenance and licence in ``tests/data/README.md``): excerpts of
cssrlib-data's files of 2021-09-22 06:30-06:36 GPST in Japan: GEONET station 3034 (Fujisawa; Trimble
NetR9: GPS C1C, Galileo C1X, QZSS C1C, Doppler), a Septentrio mosaic-X5 on a vehicle nearby
(sbf2rin: no Doppler, blank fields), and the mosaic's own mixed navigation file (sbf2rin: GPS LNAV,
Galileo I/NAV and F/NAV, QZSS). The reader is checked against the files' printed numbers; the
single-point solution per constellation against the station's published position, with tolerances
that a leap-second shift or a missing Earth-rotation term exceed (both shown). The files hold no
BeiDou or GLONASS observations: those time bases are tested in ``test_rinex_real_glo_bds.py``.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from collections import Counter
from pathlib import Path

import hatanaka
import numpy as np
import pytest

from companion.gnss.constants import C_M_S
from companion.gnss.ephemeris import EphemerisStore, attach_broadcast
from companion.gnss.geometry import geodetic_to_ecef
from companion.gnss.spp import SppConfig, geometry_at, solve_position
from companion.gnss.systems import System
from companion.gnss.timescale import gps_from_calendar
from gcs_tools.gnss import baseline, rinex
from gcs_tools.gnss.sources import rinex_input
from tests.rinex_real_helpers import enu_errors, residuals_at, row

DATA = Path(__file__).parent / "data" / "real_rinex3"
STATION_OBS = DATA / "3034265G_excerpt.21O"
ROVER_OBS = DATA / "SEPT265G_excerpt.21O"
NAV = DATA / "SEPT2650_excerpt.21P"
# GEONET 3034 (Fujisawa), ECEF (m): the base position of cssrlib's RTK example for these files (GSI's
# published coordinates); the header's APPROX POSITION XYZ is 4.4 m from it
STATION_ECEF_M = np.array([-3959400.631, 3385704.533, 3667523.111])
# the rover's starting point in cssrlib's examples (latitude, longitude in degrees, ellipsoidal height);
# the vehicle moves later (the header's APPROX POSITION is 300 m off: an older session's)
ROVER_START_ECEF_M = geodetic_to_ecef(math.radians(35.342058098), math.radians(139.521986657), 47.5515)

G, E, J = System.GPS, System.GALILEO, System.QZSS


def _t(*hms: float) -> float:
    return gps_from_calendar(2021, 9, 22, int(hms[0]), int(hms[1]), float(hms[2]), "GPS")


def _counts(epoch) -> tuple[int, int, int]:
    return tuple(int((epoch.system == s).sum()) for s in (G, E, J))  # type: ignore[return-value]


# --- the reader, against the printed files ----------------------------------------------------------


def test_station_file_reads_every_epoch_and_its_printed_values():
    """Trimble NetR9 via GEONET: no MARKER NAME, ``M: Mixed``, zero-padded seconds (``00.0000000``),
    Galileo on C1X: 4 epochs of 8 GPS, 6 Galileo, 4 QZSS, nothing refused."""
    obs = rinex.read_obs(STATION_OBS)
    assert obs.version == 3.04 and obs.time_system == "GPS" and obs.rejected == Counter()
    assert [e.t_gps_s for e in obs.epochs] == [_t(6, 30, 0), _t(6, 30, 1), _t(6, 33, 1), _t(6, 35, 59)]
    assert [_counts(e) for e in obs.epochs] == [(8, 6, 4)] * 4
    np.testing.assert_allclose(obs.approx_position_ecef_m, [-3959403.8133, 3385705.8562, 3667525.8580])
    first, last = obs.epochs[0], obs.epochs[-1]
    lam_l1 = 299792458.0 / 1575.42e6
    for epoch, system, prn, pr, dop, cn0 in [
        (first, E, 8, 26367787.992, -1880.164, 35.400),  # C1X D1X S1X
        (first, G, 13, 21530120.094, -1980.211, 46.200),
        (first, J, 7, 37265858.133, -0.555, 37.600),
        (last, G, 23, 22532756.039, 2941.109, 42.600),
    ]:
        i = row(epoch, system, prn)
        assert epoch.pseudorange_m[i] == pr and epoch.cn0_dbhz[i] == cn0
        assert epoch.pseudorange_rate_m_s[i] == pytest.approx(-dop * lam_l1, rel=1e-12)


def test_rover_file_reads_blank_fields_as_missing():
    """sbf2rin: no Doppler types, blank code fields (E12 at 06:33:02, E02 at 06:35:59: not used,
    counted), a line that stops after S1C (J03 at 06:33:04)."""
    obs = rinex.read_obs(ROVER_OBS)
    assert obs.version == 3.04 and obs.time_system == "GPS"
    assert obs.rejected == Counter({"no_pseudorange": 2})
    assert [e.t_gps_s for e in obs.epochs] == [
        _t(6, 30, 0), _t(6, 30, 1), _t(6, 33, 2), _t(6, 33, 4), _t(6, 35, 59)
    ]
    assert [_counts(e) for e in obs.epochs] == [(7, 8, 4), (7, 8, 4), (8, 7, 4), (8, 8, 4), (8, 7, 4)]
    assert 12 not in obs.epochs[2].prn[obs.epochs[2].system == E]
    assert 2 not in obs.epochs[4].prn[obs.epochs[4].system == E]
    e = obs.epochs[3]
    i = row(e, J, 3)
    assert e.pseudorange_m[i] == 37421150.840 and e.cn0_dbhz[i] == 24.781
    i = row(obs.epochs[0], E, 2)  # a code without its phase
    assert obs.epochs[0].pseudorange_m[i] == 28187222.822 and obs.epochs[0].cn0_dbhz[i] == 25.625
    assert all(np.isnan(e.pseudorange_rate_m_s).all() for e in obs.epochs)


def test_navigation_file_keeps_inav_and_counts_fnav():
    """sbf2rin's mixed file: 10 GPS, 7 Galileo I/NAV (F/NAV twins counted, nothing else), 4 QZSS;
    Galileo records whose spare fields sbf2rin leaves off (short lines) read; GPS Klobuchar, leap
    seconds from the header."""
    nav = rinex.read_nav(NAV)
    assert nav.rejected == Counter({"galileo_fnav_skipped": 7})
    by_system = Counter(System(e.system) for e in nav.kepler)
    assert by_system == Counter({G: 10, E: 7, J: 4})
    np.testing.assert_array_equal(nav.klobuchar[0], [8.3819e-09, 1.4901e-08, -5.9605e-08, -5.9605e-08])
    np.testing.assert_array_equal(nav.klobuchar[1], [8.3968e04, 1.6384e04, -1.3107e05, -6.5536e04])
    assert nav.leap_seconds == 18
    e07 = next(e for e in nav.kepler if e.system == E and e.prn == 7)
    assert e07.af0_s == -5.881445831619e-04  # the I/NAV record's E5b,E1 clock, not the F/NAV one
    assert e07.tgd_s == 5.587935447693e-09  # BGD(E5b,E1)
    assert e07.toe_gps_s == 2176 * 604800.0 + 282600.0 and e07.accuracy_m == pytest.approx(3.12)
    g24 = next(e for e in nav.kepler if e.system == G and e.prn == 24)
    assert g24.sqrt_a_m05 == 5.153716205597e03 and g24.toe_gps_s == 2176 * 604800.0 + 288000.0
    assert g24.toc_gps_s == _t(8, 0, 0) and g24.iode == 54


def test_the_store_takes_the_nearest_broadcast():
    """G05 and G13 have two sets in the file, toe 04:00 (2.5 h before the epochs, past GPS's 2 h) and
    08:00 (1.5 h after): at 06:30 the 08:00 set gives the state, as RTKLIB selects."""
    nav = rinex.read_nav(NAV)
    t = np.array([_t(6, 30, 0)] * 2)
    sys_, prn = np.array([int(G)] * 2), np.array([5, 13])
    sets = [e for e in nav.kepler if e.system == G and e.prn in (5, 13)]
    assert sorted({e.toe_gps_s - 2176 * 604800.0 for e in sets}) == [273600.0, 288000.0]
    late = EphemerisStore([e for e in sets if e.toe_gps_s == 2176 * 604800.0 + 288000.0])
    a, b = EphemerisStore(nav.kepler).states(sys_, prn, t), late.states(sys_, prn, t)
    assert a.valid.all() and b.valid.all()
    np.testing.assert_array_equal(a.pos_ecef_m, b.pos_ecef_m)
    np.testing.assert_array_equal(a.clock_s, b.clock_s)


def test_compressed_station_file_reads_as_the_plain_one(tmp_path):
    """The forms archives publish (Hatanaka + gzip) give the same epochs."""
    packed = tmp_path / "3034265G.21d.gz"
    packed.write_bytes(hatanaka.compress(STATION_OBS.read_bytes(), compression="gz"))
    a, b = rinex.read_obs(packed).epochs, rinex.read_obs(STATION_OBS).epochs
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert x.t_gps_s == y.t_gps_s
        np.testing.assert_array_equal(x.pseudorange_m, y.pseudorange_m)


# --- single-point solutions against the station's position ------------------------------------------

# (systems, horizontal m, |vertical| m): measured maxima over the 4 epochs 1.6/0.5 (all), 1.6/1.1 (GPS),
# 2.7/3.4 (Galileo, 5 satellites), 4.9/12.0 (QZSS: 4 satellites, one of them geostationary);
# without the Earth-rotation term 27-52 m horizontal; epoch times 18 s late (UTC read as GPS time) put
# every constellation's solution 6-17 km off, 1 s late still 300-950 m
TOLERANCES = [
    ((G, E, J), 4.0, 4.0),
    ((G,), 4.0, 4.0),
    ((E,), 5.0, 6.0),
    ((J,), 8.0, 20.0),
]


@pytest.fixture(scope="module")
def station():
    return rinex_input(STATION_OBS, [NAV])


@pytest.mark.parametrize(("systems", "h_tol_m", "v_tol_m"), TOLERANCES, ids=["all", "gps", "gal", "qzss"])
def test_station_solutions_per_constellation(station, systems, h_tol_m, v_tol_m):
    """Each constellation on its own (its time base, its clock) lands on the station; all four epochs."""
    assert station.rejected == Counter({"nav_galileo_fnav_skipped": 7, "no_ephemeris": 4})  # E08: none
    enu = enu_errors(station.epochs, station.klobuchar, systems, STATION_ECEF_M)
    assert len(enu) == 4
    assert np.hypot(enu[:, 0], enu[:, 1]).max() < h_tol_m
    assert np.abs(enu[:, 2]).max() < v_tol_m


def test_station_is_still_by_its_doppler(station):
    """Doppler velocity of a static antenna: measured below 0.04 m/s (all systems)."""
    for e in station.epochs:
        sol = solve_position(e, klobuchar=station.klobuchar)
        assert np.linalg.norm(sol.v_ecef_m_s) < 0.2


def test_the_tolerances_catch_a_missing_earth_rotation_and_a_leap_second(station):
    """The mistakes the known answer is there for, each beyond every tolerance above."""
    no_sagnac = enu_errors(station.epochs, station.klobuchar, (G, E, J), STATION_ECEF_M,
                            SppConfig(earth_rotation=False))
    assert np.hypot(no_sagnac[:, 0], no_sagnac[:, 1]).min() > 20.0
    obs = rinex.read_obs(STATION_OBS)
    store = station.store
    assert isinstance(store, EphemerisStore)
    shifted = [attach_broadcast(e.replace(t_gps_s=e.t_gps_s + 18.0), store)[0] for e in obs.epochs]
    for systems in ((G,), (E,), (J,)):  # measured 13-15 km, 10-17 km, 6-7 km
        enu = enu_errors(shifted, station.klobuchar, systems, STATION_ECEF_M)
        assert np.linalg.norm(enu, axis=1).min() > 1000.0


def test_rover_starts_at_its_reference_point():
    """The mosaic-X5 (another receiver, blank fields, no Doppler) at its first two epochs, before the
    vehicle moves: within the station's tolerances of cssrlib's starting point."""
    rover = rinex_input(ROVER_OBS, [NAV])
    assert rover.rejected == Counter(
        {"obs_no_pseudorange": 2, "nav_galileo_fnav_skipped": 7, "no_ephemeris": 4}  # E02: none
    )
    for systems, h_tol_m, v_tol_m in TOLERANCES[:3]:
        enu = enu_errors(rover.epochs[:2], rover.klobuchar, systems, ROVER_START_ECEF_M)
        assert np.hypot(enu[:, 0], enu[:, 1]).max() < h_tol_m
        assert np.abs(enu[:, 2]).max() < v_tol_m


def _cli(tmp_path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    truth = ",".join(f"{x:.3f}" for x in STATION_ECEF_M)
    return subprocess.run(
        [sys.executable, "-m", "gcs_tools", "gnss", "spp", str(STATION_OBS), "--nav", str(NAV),
         f"--truth-ecef={truth}", "--out", str(tmp_path / "spp"), *extra],
        capture_output=True, text=True, timeout=120,
    )


@pytest.mark.parametrize(
    ("letters", "h_tol_m", "v_tol_m", "not_selected"),
    [("", 4.0, 4.0, 0), ("G", 4.0, 4.0, 36), ("E", 5.0, 6.0, 48), ("J", 8.0, 20.0, 52)],
    ids=["all", "gps", "gal", "qzss"],
)
def test_gnss_spp_cli_on_the_station(tmp_path, letters, h_tol_m, v_tol_m, not_selected):
    """``beliefnav gnss spp --truth-ecef [--systems L]``: the same answers through the command, the
    other constellations' observations counted (4 epochs x 18 observations, less the selected)."""
    r = _cli(tmp_path, *(("--systems", letters) if letters else ()))
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "spp" / "summary.json").read_text())
    assert summary["epochs"] == 4 and summary["solutions"] == 4
    expected = {"nav_galileo_fnav_skipped": 7, "no_ephemeris": 4, "system_not_selected": not_selected}
    assert summary["rejected"] == {k: v for k, v in expected.items() if v}
    assert summary["errors"]["horizontal_m"]["p95"] < h_tol_m
    assert summary["errors"]["vertical_abs_m"]["p95"] < v_tol_m


def test_gnss_spp_cli_systems_refused(tmp_path):
    """A letter that is no constellation, and constellations the file does not hold: one line each."""
    r = _cli(tmp_path, "--systems", "GX")
    assert r.returncode == 2 and "--systems 'GX'" in r.stderr and "not one: X" in r.stderr
    r = _cli(tmp_path, "--systems", "C,R")
    assert r.returncode == 2 and "no observation of the systems CR" in r.stderr


def test_residuals_at_truth_of_raw_pseudoranges_leave_the_atmosphere_out(station):
    """A geodetic station in the open has no reflections: at its true position, with the models the
    solution uses (Saastamoinen, Klobuchar) taken off raw pseudoranges, every elevation band's median
    residual is a few metres (measured: GPS 15-30° +0.6 m, the largest QZSS 15-30° +5.0 m, one satellite
    at 16°). Before, raw RINEX residuals kept the atmosphere, +9.5 m (GPS 15-30°) and +16.6 m
    (QZSS 15-30°), which ``gnss spp`` reports as signals that arrived late (reflections)."""
    truth = np.tile(STATION_ECEF_M, (len(station.epochs), 1))
    stats = baseline.residuals_at_truth(station.epochs, truth, SppConfig(), station.klobuchar)
    medians = [b["median"] for bands in stats.values() for b in bands.values() if b["n"]]
    assert len(medians) >= 8 and max(abs(m) for m in medians) < 6.5
    assert abs(stats["GPS"]["15-30deg"]["median"]) < 2.0
    raw = baseline.residuals_at_truth(station.epochs, truth, SppConfig(tropo=False, iono=False))
    assert raw["GPS"]["15-30deg"]["median"] > 8.0  # what the atmosphere alone is worth there


def test_epoch_residuals_at_truth_of_raw_pseudoranges_leave_the_atmosphere_out(station):
    """The per-satellite residuals at the truth (the tight evaluation's tables): a geodetic station in the
    open, so every one within a few metres and each system's centred near zero (measured: at most 4.9 m,
    medians GPS −0.03, Galileo 0.00, QZSS +0.74 m). Before, raw pseudoranges kept the modelled
    atmosphere: up to 16.0 m, GPS below 30° +8.7 m, QZSS below 30° +15.7 m, read as late signals."""
    r, el, system = residuals_at(station.epochs, station.klobuchar, STATION_ECEF_M)
    assert len(r) == 68 and np.abs(r).max() < 6.0
    for s in (G, E, J):
        assert abs(np.median(r[system == s])) < 1.5
    assert abs(np.median(r[(system == G) & (el < 30.0)])) < 2.0


def test_epoch_residuals_at_truth_of_pre_corrected_pseudoranges_are_left_alone(station):
    """An epoch corrected beforehand (smartLoc's kind: satellite clock and the same atmosphere already
    taken off, ``corrected`` True) gives the raw epoch's residuals, whatever models the call names: a
    corrected pseudorange loses nothing more."""
    e = station.epochs[0]
    geo = geometry_at(e, STATION_ECEF_M, SppConfig(), station.klobuchar)
    pre = e.replace(pseudorange_m=e.pseudorange_m + C_M_S * e.sat_clock_s - geo.atm, corrected=True)
    raw = baseline.epoch_residuals_at_truth(e, STATION_ECEF_M, SppConfig(), station.klobuchar)
    for config in (SppConfig(), SppConfig(tropo=False, iono=False)):
        got = baseline.epoch_residuals_at_truth(pre, STATION_ECEF_M, config, station.klobuchar)
        assert np.allclose(got.residual_m, raw.residual_m, atol=1e-6)
        assert np.allclose(got.clock_m, raw.clock_m, atol=1e-6)
