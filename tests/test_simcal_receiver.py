"""The raw receiver's physics against known answers: geometry of reflections and shadows, diffraction,
DLL multipath and noise, Fresnel/XPD amplitudes, nominal orbits, and the whole observation model
against an independent solver (no city: the fix is the truth)."""

import math

import numpy as np
import pytest

from companion.domain.geodesy import LocalNedFrame
from companion.gnss.constants import C_M_S
from companion.gnss.spp import SppConfig, solve_position
from companion.gnss.systems import System
from companion.gnss.timescale import gps_from_calendar
from companion.mission.city3d import City, diffraction_extra_m, knife_edge_loss_db
from simvehicle.config import ReceiverConfig
from simvehicle.constellation import constellation, ephemeris_store
from simvehicle.receiver import (
    CONDUCTOR_PERMITTIVITY,
    Receiver,
    dll_multipath_chips,
    dll_sigma_m,
    reflection_amplitude,
    unobstructed_cn0_dbhz,
)

FRAME = LocalNedFrame(47.3769, 8.5417, 408.0)
T0 = gps_from_calendar(2024, 3, 20, 8, 0, 0, "UTC")
SYSTEMS = (System.GPS, System.GLONASS)


def _unit(el_deg, az_deg):
    el, az = np.radians(el_deg), np.radians(az_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])  # north, east, up


def test_image_method_extra_path_matches_the_mirrored_receiver():
    """A facade (the west face of a box at east 20 m) in front of a receiver at east 0, height 10 m:
    the extra path of the specular reflection equals |S − R'| − |S − R| for a satellite 20 000 km
    away, R' the receiver mirrored in the facade's plane; the specular point's height is checked."""
    city = City(np.array([[-100.0, 20.0, 100.0, 40.0]]), np.array([80.0]))
    p, h = np.array([0.0, 0.0]), 10.0
    for el, az in (
        (30.0, 250.0),
        (15.0, 290.0),
        (60.0, 265.0),
    ):  # satellites in the west: the facade faces them
        u = _unit(el, az)
        d = u[:2] / np.linalg.norm(u[:2])
        s, w, extra, cos_inc = city.reflections(p, h, d[None], np.array([math.tan(math.radians(el))]))
        assert list(s) == [0] and city.facades.axis[w[0]] == 1 and city.facades.sign[w[0]] == -1
        sat = np.array([0.0, 0.0, h]) + 2.0e7 * u
        rx, image = np.array([0.0, 0.0, h]), np.array([0.0, 40.0, h])  # mirrored in the plane east = 20
        expect = np.linalg.norm(sat - image) - np.linalg.norm(sat - rx)
        assert extra[0] == pytest.approx(expect, abs=1e-4)
        assert cos_inc[0] == pytest.approx(-u[1], abs=1e-12)  # u·n with the outward normal (0, −1, 0)


def test_reflection_needs_the_point_on_the_facade_and_clear_legs():
    """Too high (above the roof), the facade facing away, or a second building on a leg: no reflection."""
    tall = City(np.array([[-100.0, 20.0, 100.0, 40.0]]), np.array([80.0]))
    low = City(np.array([[-100.0, 20.0, 100.0, 40.0]]), np.array([12.0]))
    el = 40.0
    u = _unit(el, 270.0)
    d, tan = (u[:2] / np.linalg.norm(u[:2]))[None], np.array([math.tan(math.radians(el))])
    assert len(tall.reflections(np.zeros(2), 10.0, d, tan)[0]) == 1
    assert len(low.reflections(np.zeros(2), 10.0, d, tan)[0]) == 0  # specular point at 10 + 20 tan 40° > 12 m
    east = _unit(el, 90.0)
    assert len(tall.reflections(np.zeros(2), 10.0, (east[:2] / np.linalg.norm(east[:2]))[None], tan)[0]) == 0
    blocker = City(np.array([[-100.0, 20.0, 100.0, 40.0], [-5.0, 5.0, 5.0, 10.0]]), np.array([80.0, 60.0]))
    s, w, _, _ = blocker.reflections(np.zeros(2), 10.0, d, tan)  # the receiver -> facade leg is blocked ...
    assert list(blocker.facades.building[w]) == [1]  # ... (the blocker's own west face reflects instead)
    behind = City(np.array([[-100.0, 20.0, 100.0, 40.0], [-5.0, -30.0, 5.0, -20.0]]), np.array([80.0, 100.0]))
    assert len(behind.reflections(np.zeros(2), 10.0, d, tan)[0]) == 0  # facade -> satellite leg blocked


def test_line_of_sight_at_the_roof_edge_and_knife_edge_loss():
    """A roof 30 m high 10 m away: the ray at 60° elevation from 10 m clears it when tan(el)·10 > 20."""
    city = City(np.array([[-50.0, 10.0, 50.0, 30.0]]), np.array([30.0]))
    d = np.array([[0.0, 1.0]])
    for el in (30.0, 60.0, 63.3, 63.5, 64.0, 80.0):  # the edge at atan(2) = 63.43°
        tr = city.trace(np.zeros((1, 2)), np.array([10.0]), d, np.array([math.tan(math.radians(el))]), 0.19)
        assert bool(tr.blocked[0]) == (el < 63.43)
    # ITU-R P.526 known values: J(0) = 6.03 dB, J(−0.78) ~ 0, large ν ~ 13 + 20 log10 ν
    assert knife_edge_loss_db(np.array([0.0]))[0] == pytest.approx(6.02, abs=0.02)
    assert knife_edge_loss_db(np.array([-0.8, -3.0])).tolist() == [0.0, 0.0]
    assert knife_edge_loss_db(np.array([20.0]))[0] == pytest.approx(13.0 + 20 * math.log10(20.0), abs=0.2)
    # the bent path over an edge Δh above the ray at distance d: |d u + Δh z| − u·(d u + Δh z)
    el = math.radians(35.0)
    u, z = np.array([math.cos(el), math.sin(el)]), np.array([0.0, 1.0])
    e = 40.0 * u + 3.0 * z
    assert diffraction_extra_m(np.array([40.0]), np.array([3.0]), np.array([math.sin(el)]))[
        0
    ] == pytest.approx(np.linalg.norm(e) - u @ e, rel=1e-12)


def _discriminator_zero(a: float, delta: float, d: float) -> float:
    """Brute force: the zero of E − L on R(τ) + a R(τ − δ) near 0 (triangle R), by bisection."""
    r = lambda x: max(0.0, 1.0 - abs(x))  # noqa: E731
    f = lambda t: (r(t - d / 2) + a * r(t - d / 2 - delta)) - (r(t + d / 2) + a * r(t + d / 2 - delta))  # noqa: E731
    lo, hi = -d / 2 * 0.999, d / 2 * 0.999
    assert f(lo) * f(hi) <= 0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if f(lo) * f(mid) <= 0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("a", [0.5, -0.5, 0.9, -0.3])
@pytest.mark.parametrize("delta", [0.02, 0.08, 0.3, 0.95, 1.05, 1.3, -0.05, -0.5])
def test_dll_multipath_closed_form_is_the_discriminator_zero(a, delta):
    d = 0.2
    assert dll_multipath_chips(np.array([a]), np.array([delta]), d)[0] == pytest.approx(
        _discriminator_zero(a, delta, d), abs=1e-9
    )


def test_dll_noise_and_unobstructed_cn0():
    cfg = ReceiverConfig(dll_bandwidth_hz=0.5, correlator_spacing_chips=0.2, integration_s=0.02)
    c = 10**4.5
    expect = 293.0522 * math.sqrt(0.5 * 0.2 / (2 * c) * (1 + 2 / (0.02 * c * 1.8)))
    assert dll_sigma_m(np.array([45.0]), np.array([293.0522]), cfg)[0] == pytest.approx(expect, rel=1e-6)
    cn0 = unobstructed_cn0_dbhz(np.radians([90.0, 30.0, 0.0]), np.array([0, 0, 6]), cfg)
    assert cn0.tolist() == pytest.approx(
        [
            cfg.cn0_zenith_dbhz,
            cfg.cn0_zenith_dbhz - cfg.antenna_rolloff_db / 4,
            cfg.cn0_zenith_dbhz + cfg.cn0_glonass_offset_db - cfg.antenna_rolloff_db,
        ]
    )


def test_reflection_amplitude_fresnel_limits():
    eps = 5.0
    r0 = (math.sqrt(eps) - 1) / (math.sqrt(eps) + 1)
    # normal incidence: all of it turns to LHCP, rejected by the XPD at that elevation
    amp = reflection_amplitude(np.array([1.0]), np.array([0.5]), np.array([eps]), 10.0)[0]
    assert amp == pytest.approx(r0 * 10 ** (-10.0 * 0.5 / 20), rel=1e-9)
    # grazing: the handedness is kept (amplitude → 1)
    assert reflection_amplitude(np.array([1e-6]), np.array([0.5]), np.array([eps]), 10.0)[0] == pytest.approx(
        1.0, abs=1e-3
    )
    # a conductor turns all of it at every angle
    for c in (1.0, 0.5, 0.1):
        assert reflection_amplitude(np.array([c]), np.array([0.3]), np.array([CONDUCTOR_PERMITTIVITY]), 12.0)[
            0
        ] == pytest.approx(10 ** (-12.0 * 0.3 / 20), rel=1e-3)


def test_nominal_gps_ground_track_repeats_every_sidereal_day_and_glonass_orbit():
    st = ephemeris_store(T0 - 3600, T0 + 90000.0, (System.GPS,))
    sidereal = 2 * math.pi / (7.2921151467e-5 + math.radians(4.4874e-7))
    prn = np.arange(1, 25)
    a = st.states(np.zeros(24, int), prn, np.full(24, T0 + 100.0))
    b = st.states(np.zeros(24, int), prn, np.full(24, T0 + 100.0 + sidereal))
    assert np.abs(a.pos_ecef_m - b.pos_ecef_m).max() < 1.0  # the same place in the sky a sidereal day later
    assert np.linalg.norm(a.pos_ecef_m, axis=1).mean() == pytest.approx(26_560e3, rel=2e-3)
    _, glo = constellation(T0 - 3600, T0 + 3600, SYSTEMS)
    assert len({g.prn for g in glo}) == 24 and all(-7 <= g.channel <= 6 for g in glo)
    g = glo[0]
    r, v = np.array(g.pos_ecef_m), np.array(g.vel_ecef_m_s) + np.cross([0, 0, 7.292115e-5], g.pos_ecef_m)
    inc = math.degrees(math.acos(np.cross(r, v)[2] / np.linalg.norm(np.cross(r, v))))
    assert inc == pytest.approx(64.8, abs=0.3) and np.linalg.norm(r) == pytest.approx(25_508e3, rel=2e-3)
    # consecutive GLONASS ephemerides join to their quantisation (< 2 m at the switch-over)
    g1 = sorted((e for e in glo if e.prn == 1), key=lambda e: e.toe_gps_s)
    from companion.gnss.ephemeris import EphemerisStore

    for e0, e1 in zip(g1[:-1], g1[1:], strict=True):
        tm = np.array([0.5 * (e0.toe_gps_s + e1.toe_gps_s)])
        p0 = EphemerisStore([], [e0]).states(np.array([6]), np.array([1]), tm).pos_ecef_m
        p1 = EphemerisStore([], [e1]).states(np.array([6]), np.array([1]), tm).pos_ecef_m
        assert np.linalg.norm(p0 - p1) < 2.0


def _open_sky_receiver(**over):
    quiet = ("start_spread_s", "cn0_noise_db", "doppler_sigma_m_s", "sisre_m", "sisre_glonass_m",
             "iono_error_fraction", "glonass_ifb_sd_m", "clock_h0", "clock_h_2")
    cfg = ReceiverConfig(enabled=True, **{**dict.fromkeys(quiet, 0.0), **over})
    store = ephemeris_store(T0 - 3600, T0 + 3600, SYSTEMS)
    return Receiver(
        cfg, City(np.zeros((0, 4)), np.zeros(0)), FRAME, store, T0, np.random.default_rng(3)
    ), store


def test_open_sky_epoch_solves_to_the_true_position_and_velocity():
    """No buildings, no noise: the independent solver (first-order Sagnac, its own light time, broadcast
    Klobuchar and Saastamoinen) puts the antenna within 1 cm, the Doppler velocity within 2 cm/s, and
    the per-system clocks at the receiver's own offset (+ the inter-system bias)."""
    rx, store = _open_sky_receiver()
    rx.observe(0, np.zeros(3), np.zeros(3))
    p, v = np.array([30.0, -20.0, -25.0]), np.array([3.0, -1.5, 0.5])
    ep, truth = rx.observe(1_000_000, p, v)
    assert ep.n >= 12 and not truth.nlos.any() and truth.los.all()
    # the DLL noise is the only random term left: solve the noise-free pseudoranges
    ep = ep.replace(pseudorange_m=ep.pseudorange_m - truth.noise_m)
    sol = solve_position(ep, SppConfig(), klobuchar=store.klobuchar)
    assert sol.ok
    lat, lon = math.radians(FRAME.home_lat_deg), math.radians(FRAME.home_lon_deg)
    from companion.gnss.geometry import ecef_to_ned_matrix, geodetic_to_ecef

    home = geodetic_to_ecef(lat, lon, FRAME.home_alt_m)
    r = ecef_to_ned_matrix(lat, lon)
    assert np.linalg.norm(r @ (sol.p_ecef_m - home) - p) < 0.01
    assert (
        np.linalg.norm(r @ sol.v_ecef_m_s - v) < 0.02
    )  # the solver's first-order Earth rotation: ~5 mm/s a satellite
    gps = sol.clock_systems.index(System.GPS)
    assert sol.clock_bias_m[gps] == pytest.approx(C_M_S * rx.clock_bias_s, abs=0.01)
    assert sol.clock_drift_m_s == pytest.approx(C_M_S * rx.clock_drift_s_s, abs=0.01)


def test_blocked_satellite_tracked_by_its_reflection_carries_the_extra_path():
    """A street between a 40 m block (east) and a tall one (west): an eastern satellite hidden by the
    east roof is tracked by its reflection off the west block's facade, and its range error is the
    image method's extra path and nothing else (noise-free, no second path)."""
    rx, _ = _open_sky_receiver(unmapped_prob=0.0, diffraction=False)
    # east: 40 m high (blocks what its roof hides from the antenna); west: a tall facade that reflects them
    rx.city = City(
        np.array([[-500.0, 15.0, 500.0, 60.0], [-500.0, -60.0, 500.0, -15.0]]), np.array([40.0, 300.0])
    )
    rx.facade_permittivity = np.full(8, CONDUCTOR_PERMITTIVITY)
    rx.facade_absorption = np.ones(8)
    rx.observe(0, np.zeros(3), np.zeros(3))
    ep, truth = rx.observe(200_000, np.array([0.0, 0.0, -10.0]), np.zeros(3))
    assert truth.nlos.any()
    nl = truth.nlos
    az = np.radians(ep.azimuth_deg[nl])
    el = np.radians(ep.elevation_deg[nl])
    # the reflecting facade is the other side of the street: 15 m away, the extra path 2·15·cos(el)·|sin(az)|
    expect = 2 * 15.0 * np.cos(el) * np.abs(np.sin(az))
    np.testing.assert_allclose(truth.extra_path_m[nl], expect, atol=0.5)  # el/az reported in whole degrees
    np.testing.assert_allclose(truth.env_error_m[nl], truth.extra_path_m[nl], atol=1e-9)  # nothing else there


def test_clock_reset_by_one_millisecond():
    rx, _ = _open_sky_receiver()
    rx.observe(0, np.zeros(3), np.zeros(3))
    rx.clock_bias_s, rx.clock_drift_s_s = 0.4999e-3, 1e-6
    rx.observe(200_000, np.zeros(3), np.zeros(3))
    assert rx.clock_resets == 1 and rx.clock_bias_s == pytest.approx(0.4999e-3 + 0.2e-6 - 1e-3, abs=1e-12)


def test_same_seed_same_epochs_and_another_seed_another_sky():
    from companion.mission import load_mission
    from simvehicle import SimVehicle

    def epochs(seed):
        sim = SimVehicle(load_mission("test", "canyon"), 0, seed)
        out = []
        while sim.t_us < 3e6:
            out += sim.advance(None, None).gnss_raw
        return sim, out

    (a_sim, a), (_, b), (c_sim, c) = epochs(4), epochs(4), epochs(5)
    assert not np.array_equal(a[0].epoch.pseudorange_m[:3], c[0].epoch.pseudorange_m[:3])
    assert len(a) == len(b) >= 13
    for x, y in zip(a, b, strict=True):
        assert x.epoch.t_gps_s == y.epoch.t_gps_s and x.arrival_us == y.arrival_us
        for name in ("system", "prn", "pseudorange_m", "pseudorange_rate_m_s", "cn0_dbhz"):
            np.testing.assert_array_equal(getattr(x.epoch, name), getattr(y.epoch, name))
    assert a_sim.gnss.t0_gps_s != c_sim.gnss.t0_gps_s  # each seed its time of day, so its sky
    assert a[0].arrival_us - a[0].t_us == 80_000 and a[0].t_us % 200_000 == 0


def test_diffuse_fading_is_rician_with_its_factor_and_correlation():
    """The diffuse component (``diffuse_start`` / ``diffuse_step``, seeded): unit mean power at every step,
    lag-one correlation ρ, and ``|1 + g/√K|`` distributed as Rice(ν = 1, σ² = 1/(2K)) (Kolmogorov-Smirnov
    against scipy's Rice); its mean power 1 + 1/K."""
    from scipy import stats

    from simvehicle.receiver import diffuse_start, diffuse_step

    rng = np.random.default_rng(11)
    n, rho, k = 20_000, 0.6, 10.0 ** (10.0 / 10.0)
    g = diffuse_start(rng, n)
    g0 = g.copy()
    for _ in range(30):
        g_prev, g = g, diffuse_step(g, rng.standard_normal((2, n)), rho)
    assert np.mean(np.abs(g) ** 2) == pytest.approx(1.0, abs=0.03)
    lag1 = np.real(np.mean(g * np.conj(g_prev)))
    assert lag1 == pytest.approx(rho, abs=0.02)
    assert abs(np.real(np.mean(g * np.conj(g0)))) < 0.03  # 30 steps apart: forgotten (ρ³⁰ ≈ 2e-7)
    amp = np.abs(1.0 + g / math.sqrt(k))
    assert np.mean(amp**2) == pytest.approx(1.0 + 1.0 / k, rel=0.01)
    sigma = 1.0 / math.sqrt(2.0 * k)
    assert stats.kstest(amp, stats.rice(1.0 / sigma, scale=sigma).cdf).pvalue > 0.01
    # and a wrong factor is told apart: K 6 dB instead of 10 dB
    assert stats.kstest(np.abs(1.0 + g / math.sqrt(10.0 ** 0.6)), stats.rice(1.0 / sigma, scale=sigma).cdf
                        ).pvalue < 1e-6


def test_spreading_loss_of_an_unmapped_reflection():
    from simvehicle.receiver import spreading_loss_db

    np.testing.assert_allclose(spreading_loss_db(np.array([0.0, 10.0, 40.0, 80.0, 400.0]), 40.0),
                               [0.0, 0.0, 0.0, 20.0 * math.log10(2.0), 20.0], atol=1e-12)


def test_diffuse_fading_on_open_sky_spreads_cn0_as_rician_and_moves_the_code():
    """Open sky, at rest, many epochs: the line-of-sight C/N0 power over the unobstructed value averages
    1 + 1/K (K = diffuse_k_los_db; C/N0 rounded to whole dB-Hz), its spread is the Rician one, and the
    range error from the city is the diffuse component's DLL error (zero without it)."""
    k_db = 6.0
    rx, _ = _open_sky_receiver(diffuse_fading=True, diffuse_k_los_db=k_db, diffuse_time_s=0.2)
    off, _ = _open_sky_receiver()
    ratios, env, env_off = [], [], []
    for i in range(150):
        ep, tr = rx.observe(i * 200_000, np.zeros(3), np.zeros(3))
        ep0, tr0 = off.observe(i * 200_000, np.zeros(3), np.zeros(3))
        assert np.array_equal(ep.prn, ep0.prn)
        ratios.append(10.0 ** ((ep.cn0_dbhz - ep0.cn0_dbhz) / 10.0))
        env.append(tr.env_error_m)
        env_off.append(tr0.env_error_m)
    r = np.concatenate(ratios)
    k = 10.0 ** (k_db / 10.0)
    assert np.mean(r) == pytest.approx(1.0 + 1.0 / k, rel=0.05)
    sd_db = np.std(10.0 * np.log10(r))
    assert 1.5 < sd_db < 4.0  # Rician K = 6 dB: about 2.6 dB (rounding adds a little)
    assert np.all(np.concatenate(env_off) == 0.0) and np.std(np.concatenate(env)) > 0.5
    # seeded: the same seed gives the same fading, epoch by epoch
    a, _ = _open_sky_receiver(diffuse_fading=True, diffuse_k_los_db=k_db, diffuse_time_s=0.2)
    b, _ = _open_sky_receiver(diffuse_fading=True, diffuse_k_los_db=k_db, diffuse_time_s=0.2)
    for i in range(5):
        (ea, ta), (eb, tb) = (x.observe(i * 200_000, np.zeros(3), np.zeros(3)) for x in (a, b))
        np.testing.assert_array_equal(ea.cn0_dbhz, eb.cn0_dbhz)
        np.testing.assert_array_equal(ta.env_error_m, tb.env_error_m)
