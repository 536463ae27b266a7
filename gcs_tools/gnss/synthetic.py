"""A synthetic constellation and receiver (tests, benchmarks; no data set needed).

Orbits: GPS from one published broadcast ephemeris (week 2304, toe 424800 s) spread over six
planes, Galileo and BeiDou (one GEO, one IGSO-like, MEOs) Keplerian sets, GLONASS state vectors
on circular 64.8° orbits. Observations are generated independently of the solver: the exact
light-time equation with the Earth's rotation as a rotation matrix (the solver uses the
first-order Sagnac term), satellite clocks, Klobuchar and Saastamoinen delays.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from companion.gnss import EphemerisStore, GlonassEphemeris, KeplerEphemeris, make_epoch
from companion.gnss.atmosphere import iono_frequency_scale, klobuchar_m, saastamoinen_m
from companion.gnss.constants import C_M_S, OMEGA_E_RAD_S
from companion.gnss.geometry import ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from companion.gnss.systems import System
from companion.gnss.timescale import GPS_MINUS_BDT_S, gps_from_week_tow

WEEK, TOE_SOW = 2304, 424800.0
T0 = gps_from_week_tow(WEEK, TOE_SOW)
RX_ECEF = geodetic_to_ecef(math.radians(52.5), math.radians(13.4), 60.0)
KLOBUCHAR = (
    np.array([1.1176e-08, 7.4506e-09, -5.9605e-08, -5.9605e-08]),
    np.array([9.0112e04, 4.9152e04, -1.3107e05, -3.2768e05]),
)

# the published GPS ephemeris (IS-GPS-200 example values, week 2304)
BASE = dict(
    crs_m=134.75,
    delta_n_rad_s=4.12374319903e-9,
    m0_rad=-2.23037324521,
    cuc_rad=7.25500285625e-6,
    e=1.61300709005e-2,
    cus_rad=8.00378620625e-6,
    sqrt_a_m05=5153.71900558,
    cic_rad=7.07805156708e-8,
    omega0_rad=-2.84371723002,
    cis_rad=2.6635825634e-7,
    i0_rad=0.967821256634,
    crc_m=226.75,
    omega_rad=-1.2251476939,
    omega_dot_rad_s=-7.73246494535e-9,
    idot_rad_s=2.60367988229e-10,
)


def _kepler(system: System, prn: int, toe_gps: float, toe_sow: float, **over: float) -> KeplerEphemeris:
    p: dict[str, Any] = dict(BASE)
    p.update(over)
    clk: dict[str, Any] = dict(af0_s=1e-5 * ((prn * 7) % 11 - 5), af1_s_s=1e-12 * (prn % 5 - 2), af2_s_s2=0.0,
                               tgd_s=-5e-9)
    return KeplerEphemeris(
        system=int(system),
        prn=prn,
        toe_gps_s=toe_gps,
        toc_gps_s=toe_gps,
        toe_sow_s=toe_sow,
        iode=prn,
        **clk,
        **p,
    )


def constellation(t0: float = T0) -> tuple[list[KeplerEphemeris], list[GlonassEphemeris]]:
    """The constellation with every toe at GPS time ``t0`` (default: the published example's)."""
    toe_sow = t0 % 604800.0
    kep = []
    for j in range(6):
        for k in range(4):
            kep.append(
                _kepler(
                    System.GPS,
                    1 + 4 * j + k,
                    t0,
                    toe_sow,
                    omega0_rad=BASE["omega0_rad"] + j * math.pi / 3,
                    m0_rad=BASE["m0_rad"] + k * math.pi / 2 + j * 0.26,
                )
            )
    for k in range(6):
        kep.append(
            _kepler(
                System.GALILEO,
                1 + k,
                t0,
                toe_sow,
                sqrt_a_m05=5440.6,
                e=2e-4,
                i0_rad=math.radians(56),
                omega0_rad=k * 2.1,
                m0_rad=k * 1.3,
                delta_n_rad_s=3e-9,
                omega_dot_rad_s=-5.5e-9,
            )
        )
    bdt_sow = toe_sow - GPS_MINUS_BDT_S  # the same instant as BDT seconds of (BDT) week
    for prn, sqa, inc, om0, m0 in (
        (3, 6493.4, 0.03, 1.0, 2.0),
        (8, 6493.5, 0.96, 0.5, 1.2),
        (20, 5282.6, 0.96, 2.5, 0.4),
        (23, 5282.6, 0.96, 4.6, 2.2),
        (27, 5282.6, 0.96, 0.2, 4.0),
    ):
        kep.append(
            _kepler(
                System.BEIDOU,
                prn,
                t0,
                bdt_sow,
                sqrt_a_m05=sqa,
                e=5e-4,
                i0_rad=inc,
                omega0_rad=om0,
                m0_rad=m0,
                omega_dot_rad_s=-6e-9,
            )
        )
    glo = []
    r = 25_510_000.0
    vi = math.sqrt(3.9860044e14 / r)
    for k in range(6):
        node, u = k * 1.05, k * 0.7 + 0.3
        inc = math.radians(64.8)
        p = r * np.array(
            [
                math.cos(node) * math.cos(u) - math.sin(node) * math.sin(u) * math.cos(inc),
                math.sin(node) * math.cos(u) + math.cos(node) * math.sin(u) * math.cos(inc),
                math.sin(u) * math.sin(inc),
            ]
        )
        v = vi * np.array(
            [
                -math.cos(node) * math.sin(u) - math.sin(node) * math.cos(u) * math.cos(inc),
                -math.sin(node) * math.sin(u) + math.cos(node) * math.cos(u) * math.cos(inc),
                math.cos(u) * math.sin(inc),
            ]
        )
        v = v - np.cross([0.0, 0.0, 7.292115e-5], p)  # inertial -> rotating (PZ-90) velocity
        glo.append(
            GlonassEphemeris(
                prn=k + 1,
                channel=k - 3,
                toe_gps_s=t0,
                pos_ecef_m=tuple(p),
                vel_ecef_m_s=tuple(v),
                acc_ecef_m_s2=(1e-7, -2e-7, 3e-7),
                clock_bias_s=2e-5 * (k - 2),
                gamma_n=1e-12 * (k - 2),
            )
        )
    return kep, glo


def store(t0: float = T0) -> EphemerisStore:
    kep, glo = constellation(t0)
    return EphemerisStore(kep, glo, KLOBUCHAR)


CLOCKS_M = {System.GPS: 3000.0, System.GALILEO: 3012.5, System.BEIDOU: 2990.0, System.GLONASS: 3031.0}


def observe(st: EphemerisStore, t_true_s: float, rx_ecef: np.ndarray, v_rx_ecef: np.ndarray | None = None,
            **options: Any) -> tuple[Any, np.ndarray]:
    """(epoch, visible mask) of every satellite above ``mask_deg`` at TRUE receive time ``t_true_s``.

    The receiver clock is ``CLOCKS_M[GPS]`` (its time tag is true time + that / c); other systems add
    their offset. Pseudorange rates by central difference of the generator over ±1 s (the
    receiver moving at ``v_rx_ecef``), with clock drift ``drift_m_s``. ``options``: ``mask_deg``
    (10), ``atmosphere`` (True: Saastamoinen and Klobuchar delays added), ``drift_m_s`` (0), as
    ``observe_many``'s, whose one-epoch case this is."""
    v = None if v_rx_ecef is None else np.asarray(v_rx_ecef, float).reshape(1, 3)
    return observe_many(st, [t_true_s], np.asarray(rx_ecef, float).reshape(1, 3), v, **options)[0]


def observe_many(
    st: EphemerisStore,
    t_true_s: Any,
    rx_ecef: np.ndarray,
    v_rx_ecef: np.ndarray | None = None,
    mask_deg: float = 10.0,
    atmosphere: bool = True,
    drift_m_s: float = 0.0,
) -> list[tuple[Any, np.ndarray]]:
    """``observe`` at each of the times ``t_true_s`` (E,), from receiver positions ``rx_ecef`` (E, 3)
    moving at ``v_rx_ecef`` (E, 3): the same (epoch, visible mask) pairs, number for number (every
    operation is per satellite and epoch), with the satellite states of all epochs in one call per
    light-time iteration instead of one per epoch (a 669-epoch log: 14 s -> about 1 s of CPU)."""
    kep, glo = st.kepler, st.glonass
    sysv = np.array([e.system for e in kep] + [int(System.GLONASS)] * len(glo))
    prn = np.array([e.prn for e in kep] + [g.prn for g in glo])
    t_true = np.asarray(t_true_s, dtype=float).reshape(-1)
    rx_all = np.asarray(rx_ecef, dtype=float).reshape(-1, 3)
    v = np.zeros(rx_all.shape) if v_rx_ecef is None else np.asarray(v_rx_ecef, float).reshape(-1, 3)
    n_ep, n_sat = len(t_true), len(sysv)
    sys_all, prn_all = np.tile(sysv, n_ep), np.tile(prn, n_ep)
    clk0 = np.array([CLOCKS_M[System(int(x))] for x in sysv])

    def pseudoranges(dt: float) -> tuple[np.ndarray, np.ndarray]:
        t = np.repeat(t_true + dt, n_sat)
        rx = np.repeat(rx_all + v * dt, n_sat, axis=0)
        tau = np.full(n_ep * n_sat, 0.07)
        for _ in range(8):  # exact light time, Earth rotation as a rotation
            s = st.states(sys_all, prn_all, t - tau)
            ang = OMEGA_E_RAD_S * tau
            c, sn = np.cos(ang), np.sin(ang)
            rot = np.column_stack(
                (
                    c * s.pos_ecef_m[:, 0] + sn * s.pos_ecef_m[:, 1],
                    -sn * s.pos_ecef_m[:, 0] + c * s.pos_ecef_m[:, 1],
                    s.pos_ecef_m[:, 2],
                )
            )
            rho = np.linalg.norm(rot - rx, axis=1)
            tau = rho / C_M_S
        clk = np.tile(clk0 + drift_m_s * dt, n_ep)
        return (rho + clk - C_M_S * s.clock_s).reshape(n_ep, n_sat), rot.reshape(n_ep, n_sat, 3)

    pr_all, rot_all = pseudoranges(0.0)
    h = 1.0  # central difference over ±1 s: float64 GPS time resolves 0.24 µs, so a shorter
    # step would amplify that into cm/s; the range's third derivative costs < 1 mm/s here
    rate_all = (pseudoranges(h)[0] - pseudoranges(-h)[0]) / (2 * h)
    out = []
    for k in range(n_ep):
        t_k, rx_k, pr, rot, rate = float(t_true[k]), rx_all[k], pr_all[k], rot_all[k], rate_all[k]
        lat, lon, hgt = (float(x) for x in ecef_to_geodetic(rx_k))
        d = (rot - rx_k) / np.linalg.norm(rot - rx_k, axis=1)[:, None]
        enu = d @ ecef_to_enu_matrix(lat, lon).T
        el = np.arcsin(enu[:, 2])
        az = np.arctan2(enu[:, 0], enu[:, 1]) % (2 * np.pi)
        if atmosphere:
            from companion.gnss.timescale import week_tow

            atm = saastamoinen_m(lat, hgt, el) + klobuchar_m(
                *KLOBUCHAR, lat, lon, az, el, week_tow(t_k)[1]
            ) * iono_frequency_scale(sysv)
            pr = pr + atm
        vis = np.degrees(el) > mask_deg
        t_tag = t_k + CLOCKS_M[System.GPS] / C_M_S
        cn0 = 30.0 + 20.0 * np.sin(el)
        ep = make_epoch(t_tag, sysv[vis], prn[vis], pr[vis], pseudorange_rate_m_s=rate[vis],
                        cn0_dbhz=cn0[vis])
        out.append((ep, vis))
    return out
