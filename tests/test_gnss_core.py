"""companion.gnss: known answers for time scales, orbits, LNAV, the single-point solution, RAIM."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from companion.errors import UserError
from companion.gnss import EphemerisStore, SppConfig, System, attach_broadcast, make_epoch, solve_position
from companion.gnss import timescale as ts
from companion.gnss.ephemeris import glonass_derivative, kepler_states
from companion.gnss.lnav import LnavDecoder
from tests.gnss_helpers import BASE, CLOCKS_M, RX_ECEF, T0, TOE_SOW, WEEK, constellation, observe, store

# --- time scales ---------------------------------------------------------------------------------


def test_gps_week_and_calendar_known_answers():
    # 2020-01-01 was a Wednesday: GPS week 2086 began on Sunday 2019-12-29
    t = ts.gps_from_calendar(2020, 1, 1, 0, 0, 0.0, "GPS")
    assert ts.week_tow(t) == (2086, 3 * 86400.0)
    assert ts.gps_from_calendar(1980, 1, 6, 0, 0, 0.0) == 0.0
    # GPST and UTC: 18 s since 2017-01-01, 17 s just before
    assert (
        ts.gps_from_calendar(2017, 1, 1, 0, 0, 0.0, "UTC") - ts.gps_from_calendar(2017, 1, 1, 0, 0, 0.0)
        == 18.0
    )
    assert (
        ts.gps_from_calendar(2016, 12, 31, 23, 59, 59.0, "UTC")
        - ts.gps_from_calendar(2016, 12, 31, 23, 59, 59.0)
        == 17.0
    )
    assert ts.gps_from_calendar(2020, 1, 1, 0, 0, 0.0, "GLO") == t + 18.0  # RINEX GLO epochs are UTC
    # Unix: 2020-01-01T00:00:00Z = 1577836800
    assert ts.gps_to_unix_s(t + 18.0) == 1_577_836_800.0
    assert ts.unix_to_gps_s(1_577_836_800.0) == t + 18.0
    assert ts.gps_minus_utc_s(ts.unix_to_gps_s(1_483_228_800.0)) == 18.0  # 2017-01-01
    assert ts.gps_minus_utc_s(ts.unix_to_gps_s(1_483_228_799.0)) == 17.0


def test_beidou_and_week_rollover():
    # BDT week 0 began 2006-01-01 00:00:00 UTC = 00:00:14 GPST = GPS week 1356
    assert ts.bdt_to_gps_s(0.0) == ts.gps_from_calendar(2006, 1, 1, 0, 0, 14.0)
    assert ts.gps_from_calendar(2006, 1, 1, 0, 0, 0.0, "BDT") == 1356 * 604800.0 + 14.0
    assert ts.gps_to_bdt_s(ts.bdt_to_gps_s(1234.5)) == 1234.5
    # LNAV's 10-bit week: 14 in July 2019 is week 2062 (after the April 2019 rollover), 1014 in 1999
    assert ts.resolve_week(14, 1024, ts.gps_from_calendar(2019, 7, 21, 0, 0, 0.0)) == 2062
    assert ts.resolve_week(1014, 1024, ts.gps_from_calendar(1999, 6, 1, 0, 0, 0.0)) == 1014
    assert ts.resolve_week(1014, 1024, ts.gps_from_calendar(2019, 3, 1, 0, 0, 0.0)) == 2038
    assert ts.wrap_week_s(604800.0 - 30.0) == -30.0
    with pytest.raises(UserError, match="time system"):
        ts.gps_from_calendar(2020, 1, 1, 0, 0, 0.0, "TAI")


def test_boot_time_map_from_system_time_pairs():
    boot_us = np.arange(0, 600_000_000, 1_000_000, dtype=float) + 5e6
    t_gps = 1.3e9 + (boot_us - 5e6) / 1e6 * (1 - 20e-6)  # boot clock runs 20 ppm fast
    unix_us = np.array([ts.gps_to_unix_s(t) * 1e6 for t in t_gps])
    unix_us[3] = 0.0  # clock not yet set
    unix_us[10] += 5e6  # a jump
    m = ts.BootTimeMap.from_system_time(unix_us, boot_us + 300.0 * np.sin(np.arange(len(boot_us))))
    assert m.rejected == 2 and m.pairs_used == len(boot_us) - 2
    assert abs(m.boot_us(t_gps[100]) - boot_us[100]) < 400
    assert m.gps_s(m.boot_us(1.3e9 + 42.0)) == pytest.approx(1.3e9 + 42.0, abs=1e-6)
    with pytest.raises(UserError, match="pairs"):
        ts.BootTimeMap.from_system_time(np.zeros(5), np.arange(5.0))


# --- orbits ------------------------------------------------------------------------------------


def test_gps_position_published_known_answer():
    """IS-GPS-200 eph2pos example: week 2304, toe 424800 s, evaluated 30 s after toe."""
    kep, _ = constellation()
    e = next(x for x in kep if x.system == System.GPS)
    e = type(e)(
        **{
            **{f: getattr(e, f) for f in e.__slots__},
            **BASE,
            "m0_rad": BASE["m0_rad"],
            "omega0_rad": BASE["omega0_rad"],
        }
    )
    st = EphemerisStore([e])
    s = st.states(np.array([0]), np.array([e.prn]), np.array([T0 + 30.0]))
    np.testing.assert_allclose(
        s.pos_ecef_m[0], [22151566.575334515, 13275548.286060918, 7260529.645377433], atol=1e-3
    )
    assert ts.week_tow(T0 + 30.0) == (WEEK, TOE_SOW + 30.0)


def _independent_kepler(e, t):
    """IS-GPS-200 20.3.3.4.3 written out separately (scalar, bisection for Kepler, matrices for GEO)."""
    mu = {0: 3.986005e14, 2: 3.986004418e14, 3: 3.986004418e14}[e.system]
    we = {0: 7.2921151467e-5, 2: 7.2921151467e-5, 3: 7.2921150e-5}[e.system]
    a = e.sqrt_a_m05**2
    tk = t - e.toe_gps_s
    mk = e.m0_rad + (math.sqrt(mu / a**3) + e.delta_n_rad_s) * tk
    lo, hi = mk - 1.0, mk + 1.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mid - e.e * math.sin(mid) < mk else (lo, mid)
    ek = 0.5 * (lo + hi)
    nu = 2 * math.atan(math.sqrt((1 + e.e) / (1 - e.e)) * math.tan(ek / 2))
    phi = nu + e.omega_rad
    u = phi + e.cus_rad * math.sin(2 * phi) + e.cuc_rad * math.cos(2 * phi)
    r = a * (1 - e.e * math.cos(ek)) + e.crs_m * math.sin(2 * phi) + e.crc_m * math.cos(2 * phi)
    i = e.i0_rad + e.idot_rad_s * tk + e.cis_rad * math.sin(2 * phi) + e.cic_rad * math.cos(2 * phi)
    geo = e.system == 3 and (e.prn <= 5 or 59 <= e.prn <= 63)
    om = e.omega0_rad + (e.omega_dot_rad_s - (0.0 if geo else we)) * tk - we * e.toe_sow_s

    def rz(x):
        return np.array([[math.cos(x), math.sin(x), 0], [-math.sin(x), math.cos(x), 0], [0, 0, 1]])

    def rx(x):
        return np.array([[1, 0, 0], [0, math.cos(x), math.sin(x)], [0, -math.sin(x), math.cos(x)]])

    p = rz(-om) @ rx(-i) @ np.array([r * math.cos(u), r * math.sin(u), 0.0])
    if geo:
        p = rz(we * tk) @ rx(math.radians(-5.0)) @ p
    return p


def test_kepler_positions_and_velocities_against_an_independent_implementation():
    st = store()
    kep, _ = constellation()
    sysv = np.array([e.system for e in kep])
    prn = np.array([e.prn for e in kep])
    for dt in (-5000.0, 0.0, 3333.3):
        t = np.full(len(kep), T0 + dt)
        s = st.states(sysv, prn, t)
        ref = np.array([_independent_kepler(e, T0 + dt) for e in kep])
        np.testing.assert_allclose(s.pos_ecef_m, ref, atol=1e-3)  # GEO C03 included
        h = 2.0
        fd = (st.states(sysv, prn, t + h).pos_ecef_m - st.states(sysv, prn, t - h).pos_ecef_m) / (2 * h)
        np.testing.assert_allclose(s.vel_ecef_m_s, fd, atol=2e-4)
        fdc = (st.states(sysv, prn, t + h).clock_s - st.states(sysv, prn, t - h).clock_s) / (2 * h)
        np.testing.assert_allclose(s.clock_drift_s_s, fdc, atol=1e-15)
    assert 35_000e3 < np.linalg.norm(s.pos_ecef_m[prn == 3][sysv[prn == 3] == 3]) < 43_000e3


def test_clock_includes_relativity_and_group_delay():
    kep, _ = constellation()
    e = kep[0]
    tab = EphemerisStore([e])._ktab
    _, _, clk, _ = kepler_states(tab, np.array([0]), np.array([T0 + 100.0]))
    tk = 100.0
    mu = 3.986005e14
    n = math.sqrt(mu / e.sqrt_a_m05**6) + e.delta_n_rad_s
    m = e.m0_rad + n * tk
    ek = m
    for _ in range(30):
        ek = m + e.e * math.sin(ek)
    rel = -4.442807633e-10 * e.e * e.sqrt_a_m05 * math.sin(ek)
    assert clk[0] == pytest.approx(e.af0_s + e.af1_s_s * tk + rel - e.tgd_s, abs=1e-15)


def test_glonass_rk4_grid_against_an_adaptive_integrator():
    st = store()
    _, glo = constellation()
    for g in glo[:3]:
        acc = np.array([g.acc_ecef_m_s2])
        for dt in (-1700.0, -7.5, 0.0, 412.3, 1799.0):
            s = st.states(np.array([6]), np.array([g.prn]), np.array([g.toe_gps_s + dt]))
            y0 = np.r_[g.pos_ecef_m, g.vel_ecef_m_s]
            sol = (
                solve_ivp(
                    lambda t, y, acc=acc: glonass_derivative(y[None, :], acc)[0],
                    (0.0, dt),
                    y0,
                    method="DOP853",
                    rtol=1e-12,
                    atol=1e-6,
                )
                if dt
                else None
            )
            ref = sol.y[:, -1] if sol is not None else y0
            np.testing.assert_allclose(s.pos_ecef_m[0], ref[:3], atol=5e-3)
            np.testing.assert_allclose(s.vel_ecef_m_s[0], ref[3:], atol=1e-5)
            assert s.clock_s[0] == pytest.approx(g.clock_bias_s + g.gamma_n * dt, abs=1e-15)


def test_ephemeris_selection_nearest_toe_within_age():
    kep, glo = constellation()
    e0 = kep[0]
    later = type(e0)(
        **{
            **{f: getattr(e0, f) for f in e0.__slots__},
            "toe_gps_s": T0 + 7200.0,
            "toc_gps_s": T0 + 7200.0,
            "toe_sow_s": TOE_SOW + 7200.0,
            "af0_s": 1.0,
        }
    )
    sick = type(e0)(**{**{f: getattr(e0, f) for f in e0.__slots__}, "prn": 30, "health": 1})
    st = EphemerisStore([e0, later, sick], glo[:1])
    rows = st.select(
        np.array([0, 0, 0, 0, 0, 6, 6]),
        np.array([1, 1, 1, 1, 30, 1, 1]),
        np.array([T0, T0 + 3599.0, T0 + 3601.0, T0 + 7200.0 * 2 + 1, T0, T0 + 1799.0, T0 + 1801.0]),
    )
    assert list(rows) == [0, 0, 1, -1, -1, 2, -1]
    assert st.dropped_unhealthy == 1


def test_lnav_subframes_known_answer():
    """Real GPS L1 C/A subframes of PRN 21 (July 2019) as u-blox SFRBX words, and their decoded values
    (the UBLOX_read project's test vector, MIT licence)."""
    from tests.gnss_helpers_lnav import SUBFRAMES_PRN21

    dec = LnavDecoder()
    out = [dec.add(21, w, ts.gps_from_calendar(2019, 7, 20, 0, 0, 0.0)) for w in SUBFRAMES_PRN21]
    ephs = [e for e in out if e is not None]
    assert len(ephs) == 1
    e = ephs[0]
    assert (e.prn, e.iode, e.health) == (21, 78, 0)
    assert e.accuracy_m == 2.4  # URA index 0 (between the week, 14 = 2062 mod 1024, and the health)
    assert ts.week_tow(e.toe_gps_s) == (2062, 597600.0) and e.toe_gps_s == e.toc_gps_s
    assert e.sqrt_a_m05 == pytest.approx(math.sqrt(26560606.593836), abs=1e-6)
    for value, expected in (
        (e.e, 0.024511),
        (e.i0_rad, 0.949169),
        (e.omega0_rad, 2.358914),
        (e.omega_rad, -1.427803),
        (e.m0_rad, 2.311086),
        (e.af0_s, -0.000151),
    ):
        assert value == pytest.approx(expected, abs=1e-6)
    assert (e.crc_m, e.crs_m) == (340.96875, -21.46875)
    bad = list(SUBFRAMES_PRN21[0])
    bad[0] = 0
    assert dec.add(21, bad) is None and dec.counters["lnav_bad_preamble"] == 1


# --- single-point solution ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def scene():
    st = store()
    ep, _ = observe(st, T0 + 100.0, RX_ECEF, v_rx_ecef=np.array([5.0, -3.0, 1.0]), drift_m_s=0.3)
    ep, dropped = attach_broadcast(ep, st)
    assert dropped == 0 and set(ep.systems()) == {System.GPS, System.GALILEO, System.BEIDOU, System.GLONASS}
    return st, ep


def test_spp_exact_on_a_synthetic_constellation(scene):
    st, ep = scene
    for weighting in ("uniform", "cn0-elevation"):
        s = solve_position(ep, SppConfig(weighting=weighting), klobuchar=st.klobuchar)
        assert s.ok and s.n_used == ep.n
        np.testing.assert_allclose(s.p_ecef_m, RX_ECEF, atol=2e-3)
        np.testing.assert_allclose(s.clock_bias_m, [CLOCKS_M[x] for x in s.clock_systems], atol=2e-3)
        assert np.nanmax(np.abs(s.residuals_m)) < 2e-3 and s.chi2 < 1e-6
        assert 0 < s.dops.hdop < s.dops.pdop < s.dops.gdop
    # without the atmosphere models the same data are metres off (they were really applied)
    s = solve_position(ep, SppConfig(iono=False, tropo=False), klobuchar=st.klobuchar)
    assert np.linalg.norm(s.p_ecef_m - RX_ECEF) > 1.0


def test_spp_earth_rotation_matters(scene):
    st, ep = scene
    s = solve_position(ep, SppConfig(earth_rotation=False), klobuchar=st.klobuchar)
    assert np.linalg.norm(s.p_ecef_m - RX_ECEF) > 10.0


def test_doppler_velocity_known_answer(scene):
    st, ep = scene
    s = solve_position(ep, SppConfig(), klobuchar=st.klobuchar)
    # exact light-time ranges differentiated against the first-order model: 0.05 mm/s measured (with
    # RTKLIB's sign of the Sagnac rate it was ~1 cm/s)
    np.testing.assert_allclose(s.v_ecef_m_s, [5.0, -3.0, 1.0], atol=1e-3)
    assert s.clock_drift_m_s == pytest.approx(0.3, abs=1e-3)
    assert math.isfinite(s.vel_acc_m_s)


def test_raim_excludes_an_injected_100_m_fault(scene):
    st, ep = scene
    pr = ep.pseudorange_m.copy()
    bad = 3
    pr[bad] += 100.0
    faulty = ep.replace(pseudorange_m=pr)
    plain = solve_position(faulty, SppConfig(), klobuchar=st.klobuchar)
    assert np.linalg.norm(plain.p_ecef_m - RX_ECEF) > 5.0
    s = solve_position(faulty, SppConfig(raim=True), klobuchar=st.klobuchar)
    assert s.raim_passed is True and list(np.nonzero(s.excluded)[0]) == [bad] and not s.used[bad]
    np.testing.assert_allclose(s.p_ecef_m, RX_ECEF, atol=5e-3)
    assert s.residuals_m[bad] == pytest.approx(100.0, abs=0.05)
    clean = solve_position(ep, SppConfig(raim=True), klobuchar=st.klobuchar)
    assert clean.raim_passed is True and not clean.excluded.any()



def test_raim_threshold_known_answers_and_scipy_stats_not_imported_with_the_package():
    """The χ² thresholds of RAIM and the tight FDE (tables: 3.8415 at 5 %, 1 dof; 13.2767 at 1 %, 4 dof),
    and scipy.stats (~0.7 s) is not imported by the processes that only import companion.gnss."""
    import subprocess
    import sys

    from companion.gnss.spp import chi2_threshold

    assert chi2_threshold(0.05, 1) == pytest.approx(3.841458820694124, rel=1e-12)
    assert chi2_threshold(0.01, np.int64(4)) == pytest.approx(13.276704135987622, rel=1e-12)
    code = "import sys, companion.wiring, simvehicle.node; print('scipy.stats' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == "False", done.stdout + done.stderr


def test_chi2_thresholds_are_scipys_and_the_tight_navigator_does_not_import_scipy_stats():
    """chi2_threshold gives exactly chi2.ppf(1 − p, dof) at RAIM's and the tight FDE's default 1e-3 and at
    other probabilities and degrees of freedom; a tight navigator started on raw epochs (its RAIM
    single-point solution, the FDE row) never imports scipy.stats."""
    import subprocess
    import sys

    from scipy.stats import chi2

    from companion.gnss import spp

    for p in (1e-3, 2e-3, 0.05, 1e-7):
        for dof in range(1, 82):
            assert spp.chi2_threshold(p, dof) == float(chi2.ppf(1.0 - p, dof)), (p, dof)
    code = (
        "import sys\n"
        "import numpy as np\n"
        "from companion.domain.samples import AttitudeSample, ImuSample\n"
        "from companion.tight import RawGnss, TightConfig\n"
        "from companion.wiring import tight_navigator_for\n"
        "from gcs_tools.gnss.synthetic import RX_ECEF, T0, observe, store\n"
        "st = store()\n"
        "for method in ('second-order', 'fde'):\n"
        "    nav = tight_navigator_for(None, method, config=TightConfig(), ephemerides=st)\n"
        "    for i in range(3):\n"
        "        t = 1_000_000 + i * 200_000\n"
        "        nav.push(AttitudeSample(t, np.array([1.0, 0.0, 0.0, 0.0])))\n"
        "        nav.push(ImuSample(t, np.array([0.0, 0.0, -9.80665]), np.zeros(3)))\n"
        "        nav.push(RawGnss(t, observe(st, T0 + 100.0 + 0.2 * i, RX_ECEF)[0]))\n"
        "    assert nav.counters()['gnss_fused'] == 2, nav.counters()\n"
        "print('scipy.stats' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.stdout.strip() == "False", done.stdout + done.stderr


def test_a_singular_geometry_is_an_unsolved_epoch():
    """Six satellites on one line from the receiver (collinear lines of sight): the normal matrix has no
    inverse. numpy's LinAlgError crashed ``gnss spp`` and the replay; now the epoch is unsolved, with the
    reason the spp summary counts."""
    u = RX_ECEF / np.linalg.norm(RX_ECEF)
    pos = np.array([u * r for r in (2.6e7, 2.65e7, 2.7e7, 2.75e7, 2.8e7, 2.85e7)])
    ep = make_epoch(T0, [int(System.GPS)] * 6, range(1, 7), np.linalg.norm(pos - RX_ECEF, axis=1),
                    sat_pos_ecef_m=pos, corrected=True, cn0_dbhz=[45.0] * 6)
    for config in (SppConfig(), SppConfig(weighting="uniform"), SppConfig(raim=False)):
        s = solve_position(ep, config)
        assert not s.ok and s.reason == "singular geometry" and np.isnan(s.p_ecef_m).all()


def test_bad_observations_are_not_used(scene):
    st, ep = scene
    pr = ep.pseudorange_m.copy()
    pr[0] = np.nan
    pos = ep.sat_pos_ecef_m.copy()
    pos[1] = np.nan
    s = solve_position(ep.replace(pseudorange_m=pr, sat_pos_ecef_m=pos), SppConfig(), klobuchar=st.klobuchar)
    assert s.ok and not s.used[0] and not s.used[1]
    np.testing.assert_allclose(s.p_ecef_m, RX_ECEF, atol=2e-3)
    few = solve_position(
        ep.select(np.array([0, 1, 2, ep.n - 1])), SppConfig()
    )  # GPS x3 + GLONASS: 5 unknowns
    assert not few.ok and few.reason == "too few satellites" and np.isnan(few.p_ecef_m).all()
    with pytest.raises(ValueError, match="weighting"):
        SppConfig(weighting="magic")
    with pytest.raises(ValueError, match="shape"):
        make_epoch(0.0, [0, 0], [1, 2], [2e7, 2e7], cn0_dbhz=[40.0])


def test_corrected_epoch_uses_given_positions_only():
    """A smartLoc-like epoch: pre-corrected pseudoranges, given satellite positions, no ephemeris."""
    st, ep = store(), None
    ep, _ = observe(st, T0 + 50.0, RX_ECEF, atmosphere=False)
    ep, _ = attach_broadcast(ep, st)
    y = ep.pseudorange_m + 299_792_458.0 * ep.sat_clock_s
    corrected = make_epoch(
        12.3,
        ep.system,
        ep.prn,
        y,
        sat_pos_ecef_m=ep.sat_pos_ecef_m,
        cn0_dbhz=ep.cn0_dbhz,
        corrected=True,
        time_base="dataset",
    )
    s = solve_position(corrected, SppConfig())
    np.testing.assert_allclose(s.p_ecef_m, RX_ECEF, atol=2e-3)
    with pytest.raises(ValueError, match="GPS time"):
        attach_broadcast(corrected, st)
