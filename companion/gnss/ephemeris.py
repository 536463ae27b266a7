"""Broadcast ephemerides -> satellite ECEF position, velocity and clock, vectorised over satellites.

* Keplerian orbits (GPS, QZSS: IS-GPS-200 20.3.3.4.3; Galileo: OS SIS ICD 5.1.1; BeiDou: ICD B1I
  5.2.4 with the GEO satellites' own −5° rotation): position and analytic velocity; clock
  polynomial + relativistic correction ``F e √A sin E`` − group delay of the observed signal.
* GLONASS (ICD 5.1 A.3.1.2): the broadcast PZ-90 state integrated with RK4 (J2, Earth rotation,
  the broadcast luni-solar acceleration); clock ``−τ_n + γ_n (t − t_b)``. PZ-90.11 is taken as
  WGS-84 (centimetres).

Cost: everything per ephemeris that does not depend on time is computed once when an
:class:`EphemerisStore` is built (semi-major axis, mean motion, √(1−e²), Ω at the week start; for
GLONASS an RK4 grid of states every ``GLONASS_GRID_S`` seconds over the validity window), so a
query is one vectorised pass: selection by ``searchsorted``, a fixed 3-step Newton solve of
Kepler's equation, one RK4 step from the nearest GLONASS grid node. About 150 µs for 20
satellites on this project's 2-core machine (``beliefnav bench gnss``): a filter at 5 Hz can evaluate
them once per epoch, or once a second and move them with their velocity in between.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np

from companion.gnss import constants as k
from companion.gnss.observations import GnssEpoch
from companion.gnss.systems import System, is_beidou_geo

# Longest |t − toe| an ephemeris is used for (RTKLIB MAXDTOE*: s)
MAX_AGE_S: dict[System, float] = {
    System.GPS: 7200.0,
    System.QZSS: 7200.0,
    System.GALILEO: 10800.0,
    System.BEIDOU: 21600.0,
    System.GLONASS: 1800.0,
}
GLONASS_GRID_S = 30.0  # RK4 grid step of the cached GLONASS states (one ≤ 15 s step per query)
KEPLER_ITERATIONS = 3  # Newton steps from E = M + e sin M: < 1e-15 rad for e < 0.05 (GNSS orbits ≤ 0.03)
_COS5, _SIN5 = np.cos(np.deg2rad(-5.0)), np.sin(np.deg2rad(-5.0))
_KEY_SCALE = 1e10  # selection key = sv_key * this + (t − reference): 300 years per satellite


@dataclass(frozen=True, slots=True)
class KeplerEphemeris:
    """One broadcast Keplerian ephemeris (GPS LNAV, Galileo I/NAV-F/NAV, BeiDou D1/D2, QZSS).

    Times: ``toe_gps_s`` / ``toc_gps_s`` absolute GPS time; ``toe_sow_s`` seconds into the
    system's own week (BDT for BeiDou), which the node longitude refers to."""

    system: int
    prn: int
    toe_gps_s: float
    toc_gps_s: float
    toe_sow_s: float
    sqrt_a_m05: float
    e: float
    i0_rad: float
    omega0_rad: float  # longitude of the ascending node at the week start
    omega_rad: float  # argument of perigee
    m0_rad: float
    delta_n_rad_s: float
    omega_dot_rad_s: float
    idot_rad_s: float
    cuc_rad: float
    cus_rad: float
    crc_m: float
    crs_m: float
    cic_rad: float
    cis_rad: float
    af0_s: float
    af1_s_s: float
    af2_s_s2: float
    tgd_s: float = 0.0  # group delay of the observed signal (GPS TGD, GAL BGD E1/E5b, BDS TGD1)
    iode: int = 0
    health: int = 0  # 0 = healthy
    # broadcast 1σ range accuracy (GPS/BeiDou URA, Galileo SISA), metres; NaN: not given (no field, a
    # blank RINEX field: used as any other); inf: the broadcast says "no accuracy prediction" (GPS/BeiDou
    # URA index 15, Galileo NAPA or a spare SISA index): the satellite is not used (EphemerisStore)
    accuracy_m: float = math.nan


@dataclass(frozen=True, slots=True)
class GlonassEphemeris:
    """One GLONASS broadcast ephemeris (PZ-90 state at t_b)."""

    prn: int  # slot
    channel: int  # frequency channel k (−7..+6)
    toe_gps_s: float  # t_b as GPS time
    pos_ecef_m: tuple[float, float, float]
    vel_ecef_m_s: tuple[float, float, float]
    acc_ecef_m_s2: tuple[float, float, float]  # luni-solar acceleration
    clock_bias_s: float  # −τ_n (RINEX "SV clock bias")
    gamma_n: float  # relative frequency bias γ_n
    health: int = 0

    system: int = int(System.GLONASS)


class SatStates(NamedTuple):
    """Satellite states at the query times, (n, …) arrays; rows without an ephemeris are NaN."""

    pos_ecef_m: np.ndarray  # (n, 3) in the ECEF frame of the query (transmission) time
    vel_ecef_m_s: np.ndarray  # (n, 3)
    clock_s: np.ndarray  # (n,) add c·this to a pseudorange (incl. relativity and group delay)
    clock_drift_s_s: np.ndarray  # (n,)
    valid: np.ndarray  # (n,) bool: an ephemeris within its age limit was found


def _kepler_tables(ephs: list[KeplerEphemeris]) -> dict[str, np.ndarray]:
    t = {f.name: np.array([getattr(e, f.name) for e in ephs], dtype=float) for f in fields(KeplerEphemeris)}
    sys_ = t["system"].astype(int)
    mu = np.where(
        sys_ == System.GPS,
        k.MU_GPS_M3_S2,
        np.where(
            sys_ == System.QZSS,
            k.MU_GPS_M3_S2,
            np.where(sys_ == System.GALILEO, k.MU_GAL_M3_S2, k.MU_BDS_M3_S2),
        ),
    )
    we = np.where(
        sys_ == System.BEIDOU,
        k.OMEGA_E_BDS_RAD_S,
        np.where(sys_ == System.GALILEO, k.OMEGA_E_GAL_RAD_S, k.OMEGA_E_GPS_RAD_S),
    )
    a = t["sqrt_a_m05"] ** 2
    geo = (sys_ == System.BEIDOU) & is_beidou_geo(t["prn"].astype(int))
    t.update(
        a_m=a,
        n_rad_s=np.sqrt(mu / a**3) + t["delta_n_rad_s"],
        sq1e2=np.sqrt(1.0 - t["e"] ** 2),
        we_rad_s=we,
        geo=geo.astype(float),
        f_rel=-2.0 * np.sqrt(mu) / k.C_M_S**2,
        # node longitude at toe in the (rotating) frame; rate: Ω̇ − ω_e (GEO: Ω̇, rotated afterwards)
        node0=t["omega0_rad"] - we * t["toe_sow_s"],
        node_rate=np.where(geo, t["omega_dot_rad_s"], t["omega_dot_rad_s"] - we),
    )
    names = [n for n in t if n not in ("system", "prn", "iode", "health", "accuracy_m")]
    t["_matrix"] = np.vstack([t[n] for n in names])
    t["_names"] = names  # type: ignore[assignment]
    return t


def kepler_states(
    tab: dict[str, np.ndarray], rows: np.ndarray, t_gps_s: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity, clock, clock drift of Keplerian ephemeris ``rows`` at ``t_gps_s``."""
    cols = tab["_matrix"][:, rows]
    g = {name: cols[i] for i, name in enumerate(tab["_names"])}
    tk = t_gps_s - g["toe_gps_s"]
    e = g["e"]
    m = g["m0_rad"] + g["n_rad_s"] * tk
    E = m + e * np.sin(m)
    for _ in range(KEPLER_ITERATIONS):
        E -= (E - e * np.sin(E) - m) / (1.0 - e * np.cos(E))
    sE, cE = np.sin(E), np.cos(E)
    den = 1.0 - e * cE
    Edot = g["n_rad_s"] / den
    nu = np.arctan2(g["sq1e2"] * sE, cE - e)
    nudot = g["sq1e2"] * Edot / den
    phi = nu + g["omega_rad"]
    s2, c2 = np.sin(2 * phi), np.cos(2 * phi)
    u = phi + g["cus_rad"] * s2 + g["cuc_rad"] * c2
    r = g["a_m"] * den + g["crs_m"] * s2 + g["crc_m"] * c2
    i = g["i0_rad"] + g["idot_rad_s"] * tk + g["cis_rad"] * s2 + g["cic_rad"] * c2
    udot = nudot * (1.0 + 2.0 * (g["cus_rad"] * c2 - g["cuc_rad"] * s2))
    rdot = g["a_m"] * e * sE * Edot + 2.0 * nudot * (g["crs_m"] * c2 - g["crc_m"] * s2)
    idot = g["idot_rad_s"] + 2.0 * nudot * (g["cis_rad"] * c2 - g["cic_rad"] * s2)
    su, cu = np.sin(u), np.cos(u)
    xp, yp = r * cu, r * su
    xpd, ypd = rdot * cu - r * udot * su, rdot * su + r * udot * cu
    node = g["node0"] + g["node_rate"] * tk
    nd = g["node_rate"]
    sO, cO = np.sin(node), np.cos(node)
    si, ci = np.sin(i), np.cos(i)
    x = xp * cO - yp * ci * sO
    y = xp * sO + yp * ci * cO
    z = yp * si
    vx = xpd * cO - ypd * ci * sO + yp * si * sO * idot - y * nd
    vy = xpd * sO + ypd * ci * cO - yp * si * cO * idot + x * nd
    vz = ypd * si + yp * ci * idot
    pos = np.column_stack((x, y, z))
    vel = np.column_stack((vx, vy, vz))
    geo = g["geo"] > 0
    if geo.any():
        pos[geo], vel[geo] = _beidou_geo(pos[geo], vel[geo], g["we_rad_s"][geo] * tk[geo], g["we_rad_s"][geo])
    dt = t_gps_s - g["toc_gps_s"]
    rel = g["f_rel"] * e * g["sqrt_a_m05"]
    clock = g["af0_s"] + dt * (g["af1_s_s"] + dt * g["af2_s_s2"]) + rel * sE - g["tgd_s"]
    drift = g["af1_s_s"] + 2.0 * dt * g["af2_s_s2"] + rel * cE * Edot
    return pos, vel, clock, drift


def _beidou_geo(
    pg: np.ndarray, vg: np.ndarray, angle: np.ndarray, we: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """BeiDou GEO: inertial-like coordinates -> ECEF, ``Rz(ω_e t_k) · Rx(−5°)`` (ICD B1I 5.2.4.12)."""
    # Rx(−5°)
    px, py, pz = pg[:, 0], _COS5 * pg[:, 1] + _SIN5 * pg[:, 2], -_SIN5 * pg[:, 1] + _COS5 * pg[:, 2]
    vx, vy, vz = vg[:, 0], _COS5 * vg[:, 1] + _SIN5 * vg[:, 2], -_SIN5 * vg[:, 1] + _COS5 * vg[:, 2]
    s, c = np.sin(angle), np.cos(angle)
    pos = np.column_stack((c * px + s * py, -s * px + c * py, pz))
    vel = np.column_stack(
        (c * vx + s * vy + we * (-s * px + c * py), -s * vx + c * vy + we * (-c * px - s * py), vz)
    )
    return pos, vel


def glonass_derivative(state: np.ndarray, acc_m_s2: np.ndarray) -> np.ndarray:
    """d/dt of (m, 6) PZ-90 states [r, v] (GLONASS ICD A.3.1.2: J2, Earth rotation, luni-solar)."""
    x, y, z = state[:, 0], state[:, 1], state[:, 2]
    vx, vy = state[:, 3], state[:, 4]
    r2 = x * x + y * y + z * z
    r3 = r2 * np.sqrt(r2)
    a = 1.5 * k.J2_GLO * k.MU_GLO_M3_S2 * k.A_E_GLO_M**2 / r2 / r3
    b = 5.0 * z * z / r2
    c = -k.MU_GLO_M3_S2 / r3 - a * (1.0 - b)
    w = k.OMEGA_E_GLO_RAD_S
    out = np.empty_like(state)
    out[:, :3] = state[:, 3:]
    out[:, 3] = (c + w * w) * x + 2.0 * w * vy + acc_m_s2[:, 0]
    out[:, 4] = (c + w * w) * y - 2.0 * w * vx + acc_m_s2[:, 1]
    out[:, 5] = (c - 2.0 * a) * z + acc_m_s2[:, 2]
    return out


def rk4_step(state: np.ndarray, acc: np.ndarray, h_s: np.ndarray) -> np.ndarray:
    """One RK4 step of ``glonass_derivative`` with per-row step ``h_s`` (m,)."""
    h = h_s[:, None]
    k1 = glonass_derivative(state, acc)
    k2 = glonass_derivative(state + 0.5 * h * k1, acc)
    k3 = glonass_derivative(state + 0.5 * h * k2, acc)
    k4 = glonass_derivative(state + h * k3, acc)
    return state + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


class _GlonassGrid:
    """States of every GLONASS ephemeris on a grid ``toe + j·GLONASS_GRID_S``, |j·step| ≤ max age."""

    def __init__(self, ephs: list[GlonassEphemeris]) -> None:
        self.toe = np.array([e.toe_gps_s for e in ephs], dtype=float)
        self.acc = np.array([e.acc_ecef_m_s2 for e in ephs], dtype=float).reshape(-1, 3)
        self.clock0 = np.array([e.clock_bias_s for e in ephs], dtype=float)
        self.gamma = np.array([e.gamma_n for e in ephs], dtype=float)
        half = int(np.ceil(MAX_AGE_S[System.GLONASS] / GLONASS_GRID_S))
        self.half = half
        m = len(ephs)
        grid = np.empty((m, 2 * half + 1, 6))
        s0 = np.hstack(
            (
                np.array([e.pos_ecef_m for e in ephs], dtype=float).reshape(-1, 3),
                np.array([e.vel_ecef_m_s for e in ephs], dtype=float).reshape(-1, 3),
            )
        )
        grid[:, half] = s0
        for sign in (1.0, -1.0):
            s, h = s0, np.full(m, sign * GLONASS_GRID_S)
            for j in range(1, half + 1):
                s = rk4_step(s, self.acc, h)
                grid[:, half + int(sign) * j] = s
        self.grid = grid

    def states(
        self, rows: np.ndarray, t_gps_s: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        tk = t_gps_s - self.toe[rows]
        j = np.clip(np.rint(tk / GLONASS_GRID_S).astype(int), -self.half, self.half)
        s = rk4_step(self.grid[rows, j + self.half], self.acc[rows], tk - j * GLONASS_GRID_S)
        clock = self.clock0[rows] + self.gamma[rows] * tk
        return s[:, :3], s[:, 3:], clock, self.gamma[rows].copy()


class EphemerisStore:
    """All broadcast ephemerides of a session; answers satellite states for (system, prn, time).

    Selection: per satellite, the healthy ephemeris whose ``toe`` is nearest to the query time and
    within ``MAX_AGE_S`` (RTKLIB's rule); unhealthy ones are dropped when the store is built
    (``dropped_unhealthy``). A selected ephemeris whose broadcast says "no accuracy prediction"
    (``accuracy_m`` inf) gives no state (``valid`` False, as without an ephemeris; ``no_prediction``
    tells the two apart for counting): another set of the satellite is not used instead (RTKLIB too
    selects, then excludes). Build once (O(m log m)); queries are vectorised (see module doc)."""

    def __init__(
        self,
        kepler: list[KeplerEphemeris] = (),  # type: ignore[assignment]
        glonass: list[GlonassEphemeris] = (),  # type: ignore[assignment]
        klobuchar: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        n_in = len(kepler) + len(glonass)
        self.kepler = [e for e in kepler if e.health == 0]
        self.glonass = [e for e in glonass if e.health == 0]
        self.dropped_unhealthy = n_in - len(self.kepler) - len(self.glonass)
        self.klobuchar = klobuchar  # (alpha (4,), beta (4,)) GPS ionosphere parameters, or None
        self._ktab = _kepler_tables(self.kepler) if self.kepler else None
        # per global row (Kepler, then GLONASS, which broadcasts no accuracy here): no prediction
        self._no_prediction = np.array([e.accuracy_m == math.inf for e in self.kepler]
                                       + [False] * len(self.glonass), dtype=bool)
        self._any_no_prediction = bool(self._no_prediction.any())
        self._glo: _GlonassGrid | None = None
        # selection intervals: one row per ephemeris, global row = Kepler rows then GLONASS rows
        sysv = [int(e.system) for e in self.kepler] + [int(System.GLONASS)] * len(self.glonass)
        prnv = [int(e.prn) for e in self.kepler] + [int(e.prn) for e in self.glonass]
        toev = [e.toe_gps_s for e in self.kepler] + [e.toe_gps_s for e in self.glonass]
        self.n_kepler = len(self.kepler)
        self._sel_start = np.zeros(0)
        self._sel_end = np.zeros(0)
        self._sel_row = np.zeros(0, dtype=int)
        self.t_ref_s = (min(toev) - 86400.0) if toev else 0.0
        if toev:
            self._build_selection(np.array(sysv), np.array(prnv), np.array(toev, dtype=float))

    def __len__(self) -> int:
        return len(self.kepler) + len(self.glonass)

    def _build_selection(self, sysv: np.ndarray, prnv: np.ndarray, toev: np.ndarray) -> None:
        key = sysv.astype(np.int64) * 1000 + prnv
        order = np.lexsort((np.arange(len(toev)), toev, key))  # by key, toe, then input order
        key, toe, rows = key[order], toev[order], order
        # a later duplicate (same satellite, same toe) replaces an earlier one
        last = np.ones(len(key), dtype=bool)
        last[:-1] = (key[1:] != key[:-1]) | (toe[1:] != toe[:-1])
        key, toe, rows = key[last], toe[last], rows[last]
        age = np.array([MAX_AGE_S[System(int(s))] for s in sysv[rows]])
        same_prev = np.r_[False, key[1:] == key[:-1]]
        same_next = np.r_[key[1:] == key[:-1], False]
        lo = toe - age
        hi = toe + age
        mid = np.r_[0.0, 0.5 * (toe[1:] + toe[:-1])]
        lo = np.where(same_prev, np.maximum(lo, mid), lo)
        mid_next = np.r_[mid[1:], 0.0]
        hi = np.where(same_next, np.minimum(hi, mid_next), hi)
        self._sel_start = key * _KEY_SCALE + (lo - self.t_ref_s)
        self._sel_end = key * _KEY_SCALE + (hi - self.t_ref_s)
        self._sel_row = rows

    def select(self, system: np.ndarray, prn: np.ndarray, t_gps_s: np.ndarray) -> np.ndarray:
        """Global ephemeris row per query (n,), −1 where none is within its age limit."""
        q = (np.asarray(system, dtype=np.int64) * 1000 + np.asarray(prn, dtype=np.int64)) * _KEY_SCALE + (
            np.asarray(t_gps_s, dtype=float) - self.t_ref_s
        )
        i = np.searchsorted(self._sel_start, q, side="right") - 1
        ok = (
            (i >= 0) & (q < self._sel_end[np.maximum(i, 0)])
            if len(self._sel_start)
            else np.zeros(len(q), bool)
        )
        return np.where(ok, self._sel_row[np.maximum(i, 0)] if len(self._sel_row) else -1, -1)

    def no_prediction(self, system: np.ndarray, prn: np.ndarray, t_gps_s: np.ndarray) -> np.ndarray:
        """(n,) bool: the ephemeris selected at ``t_gps_s`` broadcasts "no accuracy prediction"."""
        if not self._any_no_prediction:
            return np.zeros(len(system), dtype=bool)
        t = np.asarray(t_gps_s, dtype=float) * np.ones(len(system))
        return self._without_prediction(self.select(system, prn, t))

    def _without_prediction(self, rows: np.ndarray) -> np.ndarray:
        """(n,) bool: the selected rows (−1: none) whose ephemeris has no accuracy prediction."""
        return (rows >= 0) & self._no_prediction[np.maximum(rows, 0)]

    def states(self, system: np.ndarray, prn: np.ndarray, t_gps_s: np.ndarray) -> SatStates:
        """Satellite states at GPS times ``t_gps_s`` (n,) (the transmission times); rows without an
        ephemeris, or whose ephemeris has no accuracy prediction, are NaN and not ``valid``."""
        t = np.asarray(t_gps_s, dtype=float) * np.ones(len(system))
        rows = self.select(system, prn, t)
        if self._any_no_prediction:
            rows = np.where(self._without_prediction(rows), -1, rows)
        n = len(rows)
        pos = np.full((n, 3), np.nan)
        vel = np.full((n, 3), np.nan)
        clk = np.full(n, np.nan)
        drift = np.full(n, np.nan)
        kep = (rows >= 0) & (rows < self.n_kepler)
        if kep.any():
            assert self._ktab is not None
            pos[kep], vel[kep], clk[kep], drift[kep] = kepler_states(self._ktab, rows[kep], t[kep])
        glo = rows >= self.n_kepler
        if glo.any():
            if self._glo is None:
                self._glo = _GlonassGrid(self.glonass)
            pos[glo], vel[glo], clk[glo], drift[glo] = self._glo.states(rows[glo] - self.n_kepler, t[glo])
        return SatStates(pos, vel, clk, drift, rows >= 0)

    def glonass_channel(self, prn: np.ndarray) -> np.ndarray:
        """Frequency channel k per GLONASS slot (the latest ephemeris that states it; 0 unknown)."""
        table = {e.prn: e.channel for e in self.glonass}
        return np.array([table.get(int(p), 0) for p in prn], dtype=int)


def transmission_states(store: EphemerisStore, epoch: GnssEpoch) -> tuple[SatStates, np.ndarray]:
    """Satellite states at each signal's transmission time ``t_rx − P/c − dt_sv``: one evaluation at
    ``t_rx − P/c`` moved back by the clock offset along the velocity (|dt_sv| < 1 ms, so the
    neglected acceleration term is below a micrometre). Returns the states and the times (n,)."""
    t0 = epoch.t_gps_s - epoch.pseudorange_m / k.C_M_S
    s = store.states(epoch.system, epoch.prn, t0)
    dt = np.where(s.valid, s.clock_s, 0.0)
    pos = s.pos_ecef_m - s.vel_ecef_m_s * dt[:, None]
    clock = s.clock_s - s.clock_drift_s_s * dt
    return SatStates(pos, s.vel_ecef_m_s, clock, s.clock_drift_s_s, s.valid), t0 - dt


def attach_broadcast(
    epoch: GnssEpoch, store: EphemerisStore, rejected: Counter[str] | None = None
) -> tuple[GnssEpoch, int]:
    """The epoch with satellite position/velocity/clock from ``store`` at transmission time;
    observations without a usable ephemeris are removed. Returns (epoch, number removed); with
    ``rejected`` also counts them there by reason: ``no_accuracy_prediction`` (the selected
    ephemeris broadcasts none), ``no_ephemeris`` (none within its age, or no pseudorange)."""
    if epoch.time_base != "gps":
        raise ValueError("attach_broadcast needs an epoch in GPS time")
    st, _ = transmission_states(store, epoch)
    out = epoch.replace(
        sat_pos_ecef_m=st.pos_ecef_m,
        sat_vel_ecef_m_s=st.vel_ecef_m_s,
        sat_clock_s=st.clock_s,
        sat_clock_drift_s_s=st.clock_drift_s_s,
    )
    ok = st.valid & np.isfinite(epoch.pseudorange_m)
    n_out = int((~ok).sum())
    if rejected is not None:
        n_np = 0
        if n_out:
            t0 = epoch.t_gps_s - epoch.pseudorange_m / k.C_M_S
            n_np = int((~ok & store.no_prediction(epoch.system, epoch.prn, t0)).sum())
        rejected["no_ephemeris"] += n_out - n_np
        if n_np:
            rejected["no_accuracy_prediction"] += n_np
    return out.select(ok), n_out
