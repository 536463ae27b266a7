"""Nominal GNSS constellations as broadcast ephemerides: the simulated receiver's sky (no data set).

Every satellite flies a nominal orbit of its system's published design, written as the broadcast
ephemerides a receiver would decode, quantised to the navigation message's resolution (the orbit at
GPS LNAV scale factors for every Keplerian system, which Galileo I/NAV and BeiDou D1 carry exactly;
the clock polynomial and group delay at the system's own: LNAV, I/NAV, D1 (TGD1 in 0.1 ns); GLONASS
string scale factors), so that an ephemeris sent in a navigation message and decoded again is
exactly the orbit the simulator flies:

* **GPS**: the 24 baseline slots of the GPS SPS Performance Standard (Table 3-1: right ascension of
  the node and argument of latitude at 1 July 1993 0h UTC, Greenwich hour angle 18h 36m 14.4s),
  inclination 55°, node regression −4.4874e-7 °/s, two revolutions per sidereal day (the ground
  track repeats daily), PRN 1-24 in slot order A1…F4.
* **GLONASS** (ICD 5.1): 24 slots in three planes 120° apart, eight per plane 45° apart, the planes
  phased by 15°, inclination 64.8°, 17 revolutions in 8 sidereal days; each slot's frequency
  channel (antipodal slots share one). The broadcast state every 30 min (``t_b`` at 15 and 45
  minutes past each Moscow hour) is taken from one continuous RK4 integration of the ICD's own
  force model, so consecutive ephemerides agree to their quantisation (0.5 m).
* **Galileo**: Walker 24/3/1, 29 600 km, 56°, 17 revolutions in 10 sidereal days.
* **BeiDou** (MEO only): Walker 24/3/1, 27 906 km, 55°, 13 revolutions in 7 sidereal days,
  PRN 19-30, 32-37, 41-46.

The absolute node longitudes of GLONASS, Galileo and BeiDou, every eccentricity (0.001-0.009),
argument of perigee, clock polynomial and group delay are ours (deterministic per satellite):
a representative sky, not a given day's. Keplerian ephemerides every 2 h (``toe`` on even
hours of the system's time: BeiDou's 14 s after GPS's), GLONASS every 30 min: the
``EphemerisStore``'s nearest-``toe`` rule then uses each within 1 h / 15 min of its reference time.
Galileo and BeiDou clocks wander by 4 ns (GPS, GLONASS: 100 ns): their messages' af2 field holds
no more than about 1.4e-17 s/s² (D1) / 5.4e-17 s/s² (I/NAV).

Broadcast accuracy (``BROADCAST_ACCURACY_M``), what healthy satellites of a real sky broadcast: GPS
URA index 0 (2.4 m, the interval's upper bound; RINEX files write its nominal 2.0 m), Galileo SISA
index 107 (3.12 m), BeiDou URAI 0 (2.4 m), as in the real broadcast records of the tests (a
receiver's GPS file, IGS Galileo, DLR/TUM BeiDou). Nothing in the simulator's error model uses it.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from companion.gnss import constants as k
from companion.gnss.ephemeris import EphemerisStore, GlonassEphemeris, KeplerEphemeris, rk4_step
from companion.gnss.inav import sisa_m
from companion.gnss.lnav import ura_m
from companion.gnss.systems import System
from companion.gnss.timescale import (
    GLONASS_MINUS_UTC_S,
    GPS_MINUS_BDT_S,
    gps_from_calendar,
    gps_minus_utc_s,
    gps_to_bdt_s,
)

SIDEREAL_RATE_RAD_S = k.OMEGA_E_GPS_RAD_S
KEPLER_INTERVAL_S = 7200.0  # toe spacing of the Keplerian systems
GLONASS_INTERVAL_S = 1800.0  # t_b spacing
GLONASS_STEP_S = 30.0  # RK4 step of the reference integration (the store's grid step)
SC = math.pi  # semicircle

# GPS SPS Performance Standard, Table 3-1 (epoch 1993-07-01 0h UTC): plane RAAN (deg) and the
# argument of latitude (deg) of its four slots
GPS_EPOCH_UTC = (1993, 7, 1, 0, 0, 0)
GPS_EPOCH_GHA_DEG = (18 + 36 / 60 + 14.4 / 3600) * 15.0
GPS_SLOTS: tuple[tuple[float, tuple[float, float, float, float]], ...] = (
    (272.847, (268.126, 161.786, 11.676, 41.806)),  # A
    (332.847, (80.956, 173.336, 309.976, 204.376)),  # B
    (32.847, (111.876, 11.796, 339.666, 241.556)),  # C
    (92.847, (135.226, 265.446, 35.156, 167.356)),  # D
    (152.847, (197.046, 302.596, 66.066, 333.686)),  # E
    (212.847, (238.886, 345.226, 105.206, 135.346)),  # F
)
GPS_NODE_RATE_RAD_S = math.radians(-4.4874e-7)
# GLONASS frequency channel of slots 1..24 (antipodal slots in a plane share a channel)
GLONASS_CHANNELS = (1, -4, 5, 6, 1, -4, 5, 6, -2, -7, 0, -1, -2, -7, 0, -1, 4, -3, 3, 2, 4, -3, 3, 2)
BEIDOU_MEO_PRNS = (*range(19, 31), *range(32, 38), *range(41, 47))

SYSTEM_NAMES: dict[str, System] = {
    "GPS": System.GPS,
    "GLONASS": System.GLONASS,
    "GALILEO": System.GALILEO,
    "BEIDOU": System.BEIDOU,
}


def _frac(i: int, salt: int) -> float:
    """A fixed number in [0, 1) per (satellite, purpose): the 'ours' values, without a generator."""
    return (i * 0.6180339887498949 + salt * 0.4142135623730951) % 1.0


def _q(x: float, lsb: float) -> float:
    """``x`` rounded to a multiple of ``lsb`` (a broadcast field's resolution)."""
    return round(x / lsb) * lsb


CLOCK_WANDER_S = 1e-7  # amplitude of a satellite clock's daily wander around its offset
CLOCK_PERIOD_S = 86400.0
# per Keplerian system: (clock wander s, LSB of af0, af1, af2, TGD; iode modulus): the message's own
CLOCK_MESSAGE: dict[System, tuple[float, float, float, float, float, int]] = {
    System.GPS: (CLOCK_WANDER_S, 2.0**-31, 2.0**-43, 2.0**-55, 2.0**-31, 256),
    System.GALILEO: (4e-9, 2.0**-34, 2.0**-46, 2.0**-59, 2.0**-32, 256),
    System.BEIDOU: (4e-9, 2.0**-33, 2.0**-50, 2.0**-66, 1e-10, 32),
}
# per Keplerian system: the broadcast 1σ range accuracy (m) of a healthy satellite (module doc)
BROADCAST_ACCURACY_M: dict[System, float] = {System.GPS: ura_m(0), System.GALILEO: sisa_m(107),
                                             System.BEIDOU: ura_m(0)}


def _clock(salt: int, t_gps_s: float, wander_s: float = CLOCK_WANDER_S) -> tuple[float, float, float]:
    """A satellite clock (offset s, rate s/s, half its acceleration s/s²) at ``t_gps_s``: a fixed
    offset (±0.2 ms) plus a smooth daily wander, so that consecutive broadcast polynomials join
    (to 0.1 ns at a 2 h toe spacing) whatever the date."""
    w = 2 * math.pi / CLOCK_PERIOD_S
    ph = w * t_gps_s + 2 * math.pi * _frac(salt, 4)
    a = wander_s
    return (
        4e-4 * (_frac(salt, 3) - 0.5) + a * math.sin(ph),
        a * w * math.cos(ph),
        -0.5 * a * w * w * math.sin(ph),
    )


def _vec3(v: np.ndarray, lsb: float) -> tuple[float, float, float]:
    """A broadcast vector field: three components at ``lsb`` resolution."""
    return _q(float(v[0]), lsb), _q(float(v[1]), lsb), _q(float(v[2]), lsb)


def _wrap_pi(x: float) -> float:
    return (x + math.pi) % (2 * math.pi) - math.pi


class _Walker:
    """One satellite's nominal circular orbit: node longitude in the Earth-fixed frame and argument of
    latitude, both linear in time (secular node regression; mean motion from the repeat condition)."""

    def __init__(
        self,
        inc_rad: float,
        node_rate_rad_s: float,
        revs: int,
        sidereal_days: int,
        lam0_rad: float,
        u0_rad: float,
        t0_gps_s: float,
    ) -> None:
        self.inc = inc_rad
        self.node_rate = node_rate_rad_s
        self.n = revs * (SIDEREAL_RATE_RAD_S - node_rate_rad_s) / sidereal_days
        self.lam0, self.u0, self.t0 = lam0_rad, u0_rad, t0_gps_s

    def lam(self, t: float) -> float:
        return self.lam0 + (self.node_rate - SIDEREAL_RATE_RAD_S) * (t - self.t0)

    def u(self, t: float) -> float:
        return self.u0 + self.n * (t - self.t0)

    def a_m(self, mu: float) -> float:
        return (mu / self.n**2) ** (1.0 / 3.0)


def _walker_set(
    n_planes: int,
    per_plane: int,
    phasing_deg: float,
    inc_deg: float,
    revs: int,
    days: int,
    mu: float,
    node0_deg: float,
    t0: float,
) -> list[_Walker]:
    j2_rate = _j2_node_rate(math.radians(inc_deg), revs * SIDEREAL_RATE_RAD_S / days, mu)
    out = []
    for p in range(n_planes):
        for s in range(per_plane):
            out.append(
                _Walker(
                    math.radians(inc_deg),
                    j2_rate,
                    revs,
                    days,
                    math.radians(node0_deg + p * 360.0 / n_planes),
                    math.radians(s * 360.0 / per_plane + p * phasing_deg),
                    t0,
                )
            )
    return out


def _j2_node_rate(inc_rad: float, n_rad_s: float, mu: float) -> float:
    a = (mu / n_rad_s**2) ** (1.0 / 3.0)
    return -1.5 * n_rad_s * k.J2_GLO * (k.A_E_GLO_M / a) ** 2 * math.cos(inc_rad)


def _gps_orbits() -> list[_Walker]:
    t0 = gps_from_calendar(*GPS_EPOCH_UTC, "UTC")
    gha = math.radians(GPS_EPOCH_GHA_DEG)
    return [
        _Walker(math.radians(55.0), GPS_NODE_RATE_RAD_S, 2, 1, math.radians(raan) - gha, math.radians(u), t0)
        for raan, slots in GPS_SLOTS
        for u in slots
    ]


def _kepler_params(system: System) -> tuple[float, float, float]:
    """(μ, ω_e, offset of the system's week time from GPS time) of a Keplerian system."""
    if system == System.BEIDOU:
        return k.MU_BDS_M3_S2, k.OMEGA_E_BDS_RAD_S, 1.0
    if system == System.GALILEO:
        return k.MU_GAL_M3_S2, k.OMEGA_E_GAL_RAD_S, 0.0
    return k.MU_GPS_M3_S2, k.OMEGA_E_GPS_RAD_S, 0.0


def _kepler_ephemeris(system: System, prn: int, orbit: _Walker, toe: float, index: int) -> KeplerEphemeris:
    """The broadcast ephemeris of ``orbit`` at ``toe`` (GPS time, on an hour of the system's own time)."""
    mu, we, bdt = _kepler_params(system)
    sow = (gps_to_bdt_s(toe) if bdt else toe) % k.SECONDS_PER_WEEK
    salt = int(system) * 100 + prn
    e = _q(0.001 + 0.008 * _frac(salt, 1), 2.0**-33)
    omega = _q(_wrap_pi(2 * math.pi * _frac(salt, 2)), 2.0**-31 * SC)
    sqrt_a = _q(math.sqrt(orbit.a_m(mu)), 2.0**-19)
    n0 = math.sqrt(mu) / sqrt_a**3
    delta_n = _q(orbit.n - n0, 2.0**-43 * SC)
    m0 = _q(_wrap_pi(orbit.u(toe) - omega), 2.0**-31 * SC)
    # IS-GPS-200: Ω_k = Ω0 + (Ω̇ − ω_e) t_k − ω_e t_oe; at t_k = 0 that is the node's Earth-fixed longitude
    omega0 = _q(_wrap_pi(orbit.lam(toe) + we * sow), 2.0**-31 * SC)
    omega_dot = _q(orbit.node_rate, 2.0**-43 * SC)
    wander, lsb0, lsb1, lsb2, lsb_tgd, iods = CLOCK_MESSAGE[system]
    af0, af1, af2 = _clock(salt, toe, wander)
    no_harmonics = (0.0,) * 7  # idot, cuc, cus, crc, crs, cic, cis: a nominal orbit has none
    return KeplerEphemeris(
        int(system), prn, toe, toe, sow, sqrt_a, e, _q(orbit.inc, 2.0**-31 * SC), omega0, omega, m0, delta_n,
        omega_dot, *no_harmonics, _q(af0, lsb0), _q(af1, lsb1), _q(af2, lsb2),
        _q(-1e-8 * _frac(salt, 5), lsb_tgd), index % iods, accuracy_m=BROADCAST_ACCURACY_M[system],
    )


def _kepler_sets(system: System, t_from: float, t_to: float) -> list[KeplerEphemeris]:
    t_ref = gps_from_calendar(*GPS_EPOCH_UTC, "UTC")
    if system == System.GPS:
        orbits, prns = _gps_orbits(), list(range(1, 25))
    elif system == System.GALILEO:
        orbits = _walker_set(3, 8, 15.0, 56.0, 17, 10, k.MU_GAL_M3_S2, 25.0, t_ref)
        prns = list(range(1, 25))
    else:
        orbits = _walker_set(3, 8, 15.0, 55.0, 13, 7, k.MU_BDS_M3_S2, 70.0, t_ref)
        prns = list(BEIDOU_MEO_PRNS)
    shift = GPS_MINUS_BDT_S if system == System.BEIDOU else 0.0  # toe on the system's own hours
    first = math.floor(t_from / KEPLER_INTERVAL_S)
    last = math.ceil(t_to / KEPLER_INTERVAL_S)
    return [
        _kepler_ephemeris(system, prn, orb, j * KEPLER_INTERVAL_S + shift, j)
        for j in range(first, last + 1)
        for prn, orb in zip(prns, orbits, strict=True)
    ]


def _glonass_sets(t_from: float, t_to: float) -> list[GlonassEphemeris]:
    """Ephemerides at every t_b in [t_from, t_to] (± one interval), from one RK4 integration."""
    mu = k.MU_GLO_M3_S2
    t_ref = gps_from_calendar(*GPS_EPOCH_UTC, "UTC")
    orbits = _walker_set(3, 8, 15.0, 64.8, 17, 8, mu, 10.0, t_ref)
    # t_b at 15 and 45 minutes past each Moscow hour, as GPS times
    shift = GLONASS_MINUS_UTC_S - gps_minus_utc_s(t_from)  # Moscow time − GPS time
    phase = 900.0
    first = math.floor((t_from + shift - phase) / GLONASS_INTERVAL_S) - 1
    last = math.ceil((t_to + shift - phase) / GLONASS_INTERVAL_S) + 1
    tbs = [j * GLONASS_INTERVAL_S + phase - shift for j in range(first, last + 1)]
    # the nominal state at the first t_b (circular orbit; Earth-fixed position and velocity)
    t = tbs[0]
    states = []
    for o in orbits:
        lam, u, a = o.lam(t), o.u(t), o.a_m(mu)
        cl, sl, cu, su, ci, si = (
            math.cos(lam),
            math.sin(lam),
            math.cos(u),
            math.sin(u),
            math.cos(o.inc),
            math.sin(o.inc),
        )
        r = a * np.array([cl * cu - sl * su * ci, sl * cu + cl * su * ci, su * si])
        v_in = a * o.n * np.array([-cl * su - sl * cu * ci, -sl * su + cl * cu * ci, cu * si])
        v = v_in - np.cross([0.0, 0.0, k.OMEGA_E_GLO_RAD_S], r)  # inertial-like -> Earth-fixed velocity
        states.append(np.r_[r, v])
    s = np.array(states)
    n = len(orbits)
    acc = np.array(
        [
            [1e-6 * (_frac(i, 6) - 0.5), 1e-6 * (_frac(i, 7) - 0.5), 1e-6 * (_frac(i, 8) - 0.5)]
            for i in range(n)
        ]
    )
    acc = np.rint(acc / (2.0**-30 * 1e3)) * (2.0**-30 * 1e3)  # the broadcast resolution
    steps = round(GLONASS_INTERVAL_S / GLONASS_STEP_S)
    h = np.full(n, GLONASS_STEP_S)
    out = []
    for j, tb in enumerate(tbs):
        if j:
            for _ in range(steps):
                s = rk4_step(s, acc, h)
        for i in range(n):
            slot = i + 1
            offset, rate, _ = _clock(1000 + slot, tb)
            out.append(
                GlonassEphemeris(
                    prn=slot,
                    channel=GLONASS_CHANNELS[i],
                    toe_gps_s=tb,
                    pos_ecef_m=_vec3(s[i, :3], 2.0**-11 * 1e3),
                    vel_ecef_m_s=_vec3(s[i, 3:], 2.0**-20 * 1e3),
                    acc_ecef_m_s2=_vec3(acc[i], 2.0**-30 * 1e3),
                    clock_bias_s=_q(offset, 2.0**-30),
                    gamma_n=_q(rate, 2.0**-40),
                )
            )
    return out


@lru_cache(maxsize=8)
def constellation(
    t_from_gps_s: float, t_to_gps_s: float, systems: tuple[System, ...]
) -> tuple[tuple[KeplerEphemeris, ...], tuple[GlonassEphemeris, ...]]:
    """Broadcast ephemerides of ``systems`` covering [t_from, t_to] (GPS time)."""
    kep: list[KeplerEphemeris] = []
    glo: list[GlonassEphemeris] = []
    for s in systems:
        if s == System.GLONASS:
            glo = _glonass_sets(t_from_gps_s, t_to_gps_s)
        elif s in (System.GPS, System.GALILEO, System.BEIDOU):
            kep += _kepler_sets(s, t_from_gps_s, t_to_gps_s)
        else:
            raise ValueError(f"no nominal constellation for {s.name}")
    return tuple(kep), tuple(glo)


# Broadcast ionosphere parameters (a mid-latitude daytime set) in their LNAV units, so exact
KLOBUCHAR = (
    np.array([12 * 2.0**-30, 1 * 2.0**-27, -1 * 2.0**-24, -1 * 2.0**-24]),
    np.array([44 * 2.0**11, 3 * 2.0**14, -2 * 2.0**16, -5 * 2.0**16]),
)


@lru_cache(maxsize=8)
def ephemeris_store(t_from_gps_s: float, t_to_gps_s: float, systems: tuple[System, ...]) -> EphemerisStore:
    """An ``EphemerisStore`` of :func:`constellation` with the Klobuchar set (cached per process)."""
    kep, glo = constellation(t_from_gps_s, t_to_gps_s, systems)
    return EphemerisStore(list(kep), list(glo), KLOBUCHAR)
