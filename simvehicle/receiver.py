"""A raw GNSS receiver in the 3-D city: per-satellite pseudorange, Doppler, C/N0, elevation/azimuth.

Pure numeric core (no I/O), vectorised over satellites, seeded. One :meth:`Receiver.observe` per
measurement epoch at the vehicle's TRUE position, velocity and time:

1. **Sky**: the broadcast orbits of :mod:`simvehicle.constellation`; each signal's exact light time
   with the Earth's rotation during the flight (the satellite state at ``t − 75 ms`` moved along its
   velocity; < 0.1 mm), elevation and azimuth in the mission's NED frame.
2. **Paths** (:mod:`companion.mission.city3d`): the direct path (clear, or bent over the dominant roof edge
   with knife-edge loss), the strongest specular facade reflection, and, for a blocked satellite
   without one, an unmapped reflection with probability ``unmapped_prob`` per blocked episode
   (its extra path and phase drawn once per episode from the satellite's own stream: common random
   numbers, so two paths through the same sky meet the same reflections).
3. **Signal**: amplitudes relative to the unobstructed signal, ``10^(−loss/20)`` (diffraction,
   :func:`reflection_amplitude` for facades, unmapped); the receiver tracks the strongest (NLOS when that is
   a reflection: the range error is its whole extra path); the second strongest is multipath on it,
   with relative amplitude ``α``, delay ``δ`` and carrier phase ``θ = 2π δ / λ (+ π for a reflection
   on a direct signal)`` — from the geometry, so it fades as the vehicle moves and barely changes at
   rest. C/N0 = the antenna's unobstructed value at that elevation + ``20 log10 |1 + α R(δ) e^{iθ}|``
   (``R`` the code correlation triangle) + the tracked component's loss + noise; below
   ``cn0_threshold_dbhz`` the signal is lost, and a signal not tracked is acquired only from
   ``cn0_acquire_dbhz`` (a receiver's acquisition needs a stronger signal than its tracking). Optional
   (docs/simcal.md, "C/N0 that tells the error"): an unmapped reflection loses
   :func:`spreading_loss_db` of its extra path (``unmapped_spreading_ref_m``), and with
   ``diffuse_fading`` every tracked signal carries a diffuse Rician component (:func:`diffuse_step`)
   that enters C/N0 and the DLL like the second path.
4. **Code**: the early-minus-late DLL's multipath error on the correlation triangle
   (:func:`dll_multipath_chips`, closed form) + thermal noise (:func:`dll_sigma_m`), both in the
   signal's own chips (GLONASS chips are twice as long as GPS's: twice the multipath error).
5. **Errors every receiver shares**: broadcast orbit/clock error per satellite (SISRE), the
   ionosphere's departure from Klobuchar, Saastamoinen troposphere, GLONASS inter-frequency biases.
6. **Clock**: a TCXO (two-state random walk with Allan coefficients ``h0``, ``h−2``), offset reset
   by 1 ms when beyond ±0.5 ms (u-blox's unsteered clock; ``clock_resets`` counts them).

Pseudorange ``P = ρ + c (b_rx − dt_sv) + I + T + SISRE + ifb + e_env + n``; pseudorange rate from
the range rate of the tracked path (a reflection's arrives from the mirrored direction) + the clock
drifts + noise ``∝ 10^((45 − C/N0)/20)``. The epoch carries what a u-blox receiver reports: C/N0 in
whole dB-Hz, elevation and azimuth in whole degrees (NAV-SAT), the pseudorange variance as
``(0.01 · 2^prStd)²`` of the tracking noise it knows (RXM-RAWX); its time tag is the receiver's
clock reading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.gnss.atmosphere import iono_frequency_scale, klobuchar_m, saastamoinen_m
from companion.gnss.constants import (
    C_M_S,
    DFREQ_G1_HZ,
    FREQ_B1I_HZ,
    FREQ_G1_HZ,
    FREQ_L1_HZ,
    MU_GPS_M3_S2,
    OMEGA_E_RAD_S,
)
from companion.gnss.ephemeris import EphemerisStore, SatStates
from companion.gnss.geometry import ecef_to_ned_matrix, geodetic_to_ecef
from companion.gnss.observations import GnssEpoch, make_epoch
from companion.gnss.spp import SppSolution
from companion.gnss.systems import System
from companion.gnss.timescale import week_tow
from companion.mission.city3d import City, diffraction_extra_m, knife_edge_loss_db
from simvehicle.config import ReceiverConfig
from simvehicle.constellation import SYSTEM_NAMES

CHIP_RATE_HZ = {System.GPS: 1.023e6, System.GALILEO: 1.023e6, System.BEIDOU: 2.046e6, System.GLONASS: 0.511e6}
T_LIGHT0_S = 0.075  # satellite states evaluated this long before reception, then moved along their velocity
LIGHT_TIME_ITERATIONS = 3  # passes of the light-time equation from the 75 ms guess (< 1 µm)
MS_RESET_S = 1e-3
CN0_REF_DBHZ = 45.0
WAVELENGTH_L1_M = C_M_S / FREQ_L1_HZ  # the diffraction's wavelength (G1 and B1I differ by < 3 %)
CONDUCTOR_PERMITTIVITY = 1e12  # a conductor's Fresnel coefficients (r_s = −1, r_p = 1) as a dielectric limit
SKY_REFRESH_S = 2.0  # the broadcast orbits are evaluated this often, Taylor-moved in between


def dll_multipath_chips(a: np.ndarray, delta_chips: np.ndarray, spacing_chips: float) -> np.ndarray:
    """Code tracking error (chips) of a coherent early-minus-late DLL with spacing ``d`` on the
    ideal triangle correlation when a second component of relative in-phase amplitude
    ``a = α cos θ`` (|a| < 1) arrives ``δ`` chips after the tracked one (before it: δ < 0, by symmetry).
    The discriminator's zero, piecewise:

    * ``|δ| ≤ d (1 + a) / 2``: ``a δ / (1 + a)``;
    * up to ``1 − d (1 − a) / 2``: ``a d / 2`` (the envelope's plateau);
    * up to ``1 + d/2``: ``a (1 + d/2 − |δ|) / (2 − a)``; beyond, 0.
    """
    d = spacing_chips
    x = np.abs(delta_chips)
    out = np.where(
        x <= d * (1.0 + a) / 2.0,
        a * x / (1.0 + a),
        np.where(
            x <= 1.0 - d * (1.0 - a) / 2.0,
            a * d / 2.0,
            np.where(x < 1.0 + d / 2.0, a * (1.0 + d / 2.0 - x) / (2.0 - a), 0.0),
        ),
    )
    return np.sign(delta_chips) * out


def dll_sigma_m(cn0_dbhz: np.ndarray, chip_m: np.ndarray, cfg: ReceiverConfig) -> np.ndarray:
    """Thermal code noise (m, 1σ) of a non-coherent early-minus-late DLL (Betz and Kolodziej):
    ``chip · sqrt(B d / (2 C/N0) · (1 + 2 / (T C/N0 (2 − d))))``."""
    c = 10.0 ** (np.asarray(cn0_dbhz) / 10.0)
    d = cfg.correlator_spacing_chips
    return chip_m * np.sqrt(
        cfg.dll_bandwidth_hz * d / (2.0 * c) * (1.0 + 2.0 / (cfg.integration_s * c * (2.0 - d)))
    )


def unobstructed_cn0_dbhz(el_rad: np.ndarray, system: np.ndarray, cfg: ReceiverConfig) -> np.ndarray:
    """C/N0 of a clear line of sight: zenith value, less the antenna roll-off (1 − sin el)²."""
    base = np.where(
        system == System.GLONASS, cfg.cn0_zenith_dbhz + cfg.cn0_glonass_offset_db, cfg.cn0_zenith_dbhz
    )
    return base - cfg.antenna_rolloff_db * (1.0 - np.sin(np.maximum(el_rad, 0.0))) ** 2


def reflection_amplitude(
    cos_inc: np.ndarray, sin_el: np.ndarray, permittivity: np.ndarray, xpd_zenith_db: float
) -> np.ndarray:
    """Amplitude the antenna receives of a reflected RHCP signal, relative to the direct one at the
    same elevation: Fresnel coefficients of a smooth dielectric of relative permittivity ``ε`` at
    incidence ``θ`` (``cos θ = |u·n|``), ``r_s = (cos θ − √(ε − sin²θ)) / (cos θ + √(ε − sin²θ))``,
    ``r_p = (ε cos θ − √(ε − sin²θ)) / (ε cos θ + √(ε − sin²θ))``; the reflected wave keeps its
    handedness with amplitude ``|r_s + r_p| / 2`` (RHCP, the antenna's) and turns with
    ``|r_p − r_s| / 2`` (LHCP: all of it at normal incidence, none at grazing), the LHCP part
    rejected by the antenna's cross-polar discrimination ``xpd_zenith_db · sin el`` (powers add).
    A conductor (``ε`` → ∞) turns all of it."""
    c = np.clip(cos_inc, 1e-6, 1.0)
    root = np.sqrt(permittivity - (1.0 - c * c))
    r_s = (c - root) / (c + root)
    r_p = (permittivity * c - root) / (permittivity * c + root)
    co, cross = 0.5 * (r_s + r_p), 0.5 * (r_p - r_s)
    return np.sqrt(co * co + cross * cross * 10.0 ** (-xpd_zenith_db * np.maximum(sin_el, 0.0) / 10.0))


def spreading_loss_db(extra_m: np.ndarray, ref_m: float) -> np.ndarray:
    """Extra loss of a diffusely scattered path of extra length ``extra_m``: ``20 log10(δ / ref)`` beyond
    ``ref_m`` (a scatterer's power falls with the square of its distance, which grows with the extra
    path), 0 up to it."""
    return 20.0 * np.log10(np.maximum(np.asarray(extra_m, dtype=float), ref_m) / ref_m)


def diffuse_start(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` independent circular complex Gaussians of unit mean power (the stationary state)."""
    return (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / math.sqrt(2.0)


def diffuse_step(g: np.ndarray, w: np.ndarray, rho: float) -> np.ndarray:
    """One Gauss-Markov step of unit-power circular complex Gaussians: ``ρ g + sqrt((1 − ρ²)/2) (w0 + i w1)``
    (``w`` (2, n) standard normals); stationary: E|g|² stays 1, so ``|1 + g / sqrt(K)|²`` is Rician with
    factor K."""
    return rho * g + math.sqrt((1.0 - rho * rho) / 2.0) * (w[0] + 1j * w[1])


def prstd_index(sigma_m: np.ndarray) -> np.ndarray:
    """u-blox RXM-RAWX ``prStd`` (4 bits): the reported σ is ``0.01 · 2^prStd`` m."""
    return np.clip(np.rint(np.log2(np.maximum(sigma_m, 0.01) / 0.01)), 0, 15).astype(int)


@dataclass(frozen=True, slots=True)
class SatTruth:
    """What the simulator knows about each observation of an epoch (its row order)."""

    los: np.ndarray  # (n,) bool: the direct path is clear
    nlos: np.ndarray  # (n,) bool: the tracked signal is a reflection (mapped or not)
    env_error_m: np.ndarray  # (n,) range error from the city: tracked path's extra length + DLL multipath
    noise_m: np.ndarray  # (n,) tracking noise drawn
    common_error_m: np.ndarray  # (n,) SISRE + ionosphere model error + GLONASS inter-frequency bias
    range_m: np.ndarray  # (n,) geometric range (Earth rotation included) to the true antenna position
    extra_path_m: np.ndarray  # (n,) extra length of the tracked path alone
    model_atmosphere_m: np.ndarray  # (n,) broadcast Klobuchar + Saastamoinen here: what the receiver removes


@dataclass(frozen=True, slots=True, eq=False)
class RawObservation:
    """One measurement epoch as the receiver reports it, and the truth behind it."""

    t_us: int  # true measurement time on the vehicle's boot clock
    arrival_us: int  # when it was released (the physics tick it arrives at)
    epoch: GnssEpoch  # receiver time tag, pseudoranges, rates, C/N0, el/az, variances (no satellite states)
    truth: SatTruth
    t_gps_s: float  # true GPS time of the measurement (epoch.t_gps_s − clock_bias_s)
    clock_bias_s: float  # the receiver clock's offset at the measurement
    clock_drift_s_s: float
    solution: SppSolution | None = None  # the receiver's own single-point solution (None: no fix)
    lock_ms: np.ndarray | None = None  # (n,) time since each signal was acquired (RXM-RAWX locktime)
    clock_reset: bool = False  # the receiver clock was reset by 1 ms since the previous epoch


class Receiver:
    """The receiver's state (clock, tracking, episodes) and its per-epoch observation model."""

    def __init__(
        self,
        cfg: ReceiverConfig,
        city: City,
        frame: LocalNedFrame,
        store: EphemerisStore,
        t0_gps_s: float,
        rng: np.random.Generator,
    ) -> None:
        self.cfg = cfg
        self.city = city
        self.store = store
        self.t0_gps_s = t0_gps_s
        systems = tuple(SYSTEM_NAMES[s] for s in cfg.systems)
        keys = sorted(
            {(int(e.system), int(e.prn)) for e in store.kepler if System(e.system) in systems}
            | {(int(System.GLONASS), int(g.prn)) for g in store.glonass if System.GLONASS in systems}
        )
        self.system = np.array([s for s, _ in keys], dtype=np.int8)
        self.prn = np.array([p for _, p in keys], dtype=np.int16)
        n = len(keys)
        channel = np.where(self.system == System.GLONASS, store.glonass_channel(self.prn), 0)
        self.channel = channel
        freq = np.select(
            [self.system == System.GLONASS, self.system == System.BEIDOU],
            [FREQ_G1_HZ + channel * DFREQ_G1_HZ, np.full(n, FREQ_B1I_HZ)],
            FREQ_L1_HZ,
        )
        self.wavelength_m = C_M_S / freq
        self.chip_m = C_M_S / np.array([CHIP_RATE_HZ[System(int(s))] for s in self.system])
        self.iono_scale = iono_frequency_scale(self.system, channel)
        lat, lon = math.radians(frame.home_lat_deg), math.radians(frame.home_lon_deg)
        self.lat_rad, self.lon_rad = lat, lon
        self.home_ecef_m = geodetic_to_ecef(lat, lon, frame.home_alt_m)
        self.ecef_to_ned = ecef_to_ned_matrix(lat, lon)
        self.home_alt_m = frame.home_alt_m
        # per-flight draws: facade losses, common errors, clock (shared stream), then one stream per satellite
        g = rng
        w = len(city.facades)
        self.facade_permittivity = np.where(
            g.uniform(size=w) < cfg.metal_facade_fraction, CONDUCTOR_PERMITTIVITY, cfg.facade_permittivity
        )
        self.facade_absorption = 10.0 ** (
            -np.maximum(cfg.facade_absorption_db + cfg.facade_absorption_sd_db * g.standard_normal(w), 0.0)
            / 20.0
        )
        sisre = np.where(self.system == System.GLONASS, cfg.sisre_glonass_m, cfg.sisre_m)
        self.sisre_m = sisre * g.standard_normal(n)
        self.iono_factor = 1.0 + cfg.iono_error_fraction * g.standard_normal(n)
        ifb = cfg.glonass_ifb_sd_m * g.standard_normal(14)  # channels −7..+6
        self.ifb_m = np.where(self.system == System.GLONASS, ifb[channel + 7], 0.0)
        isb = {int(s): (0.0 if s == System.GPS else 30.0 * float(g.standard_normal())) for s in systems}
        self.isb_all_m = np.array([isb[int(s)] for s in self.system])  # inter-system clock offsets (m)
        self.clock_bias_s = float(g.uniform(-0.4e-3, 0.4e-3))
        self.clock_drift_s_s = cfg.clock_drift0_s_s * float(g.standard_normal())
        self.clock_resets = 0
        self._noise = g.spawn(1)[0]  # per-epoch draws: a fixed block per epoch, whatever is visible
        self._episode_rngs = g.spawn(n)
        self._blocked = np.zeros(n, dtype=bool)
        self._unmapped = np.zeros(n, dtype=bool)
        self._unmapped_delay_m = np.zeros(n)
        self._unmapped_phase = np.zeros(n)
        self._lock_start_us = np.full(n, -1, dtype=np.int64)
        if cfg.diffuse_fading:  # its own stream (spawned only then: the other draws stay as they were)
            self._fade_rng = g.spawn(1)[0]
            self._fade = diffuse_start(self._fade_rng, n)
            self._fade_delay_m = self._fade_rng.exponential(cfg.diffuse_delay_mean_m, n)
            self._fade_t_us: int | None = None
        self._t_us: int | None = None
        self._sky_cache: tuple[float, SatStates, np.ndarray] | None = None
        self._tau = np.full(n, T_LIGHT0_S)
        self._atm_cache: tuple[float, np.ndarray, np.ndarray, float] | None = None
        self.lock_ms = np.zeros(0)  # per row of the last epoch: time since lock (RXM-RAWX locktime)

    def _diffuse(self, t_us: int) -> np.ndarray:
        """Every satellite's diffuse component (complex, unit mean power) at ``t_us``, moved on from the
        previous epoch (Gauss-Markov, ``diffuse_time_s``; a fixed count of draws per epoch)."""
        w = self._fade_rng.standard_normal((2, len(self._fade)))
        dt = 0.0 if self._fade_t_us is None else max(t_us - self._fade_t_us, 0) * 1e-6
        self._fade_t_us = t_us
        self._fade = diffuse_step(self._fade, w, math.exp(-dt / self.cfg.diffuse_time_s))
        return self._fade

    # -- clock -------------------------------------------------------------------------------------
    def _advance_clock(self, t_us: int, n0: float, n1: float) -> bool:
        """Move the clock to ``t_us`` with the standard normals ``n0``, ``n1``; True when the
        previous epoch was the last one (its light times are a good start)."""
        if self._t_us is None:
            self._t_us = t_us
            return False
        dt = (t_us - self._t_us) * 1e-6
        self._t_us = t_us
        if dt <= 0:
            return dt == 0
        cfg = self.cfg
        q_b = cfg.clock_h0 / 2.0 * dt
        q_d = 2.0 * math.pi**2 * cfg.clock_h_2 * dt
        self.clock_bias_s += self.clock_drift_s_s * dt + math.sqrt(q_b) * n0
        self.clock_drift_s_s += math.sqrt(q_d) * n1
        if abs(self.clock_bias_s) > 0.5 * MS_RESET_S:
            self.clock_bias_s -= math.copysign(MS_RESET_S, self.clock_bias_s)
            self.clock_resets += 1
        return dt <= 1.0

    def _sky(self, t_gps_s: float) -> SatStates:
        """Satellite states at ``t_gps_s``: the store evaluated at most every ``SKY_REFRESH_S`` and
        moved on by a second-order Taylor step (two-body gravity with the Earth-fixed frame's
        Coriolis and centrifugal terms; the neglected J2 and jerk terms stay below 0.1 mm)."""
        c = self._sky_cache
        if c is None or abs(t_gps_s - c[0]) > SKY_REFRESH_S / 2:
            st = self.store.states(self.system, self.prn, np.full(len(self.system), t_gps_s))
            r = st.pos_ecef_m
            rn = np.linalg.norm(r, axis=1)[:, None]
            w = np.array([0.0, 0.0, OMEGA_E_RAD_S])
            acc = -MU_GPS_M3_S2 * r / rn**3 - 2.0 * np.cross(w, st.vel_ecef_m_s) - np.cross(w, np.cross(w, r))
            self._sky_cache = c = (t_gps_s, st, acc)
        t_ref, st, acc = c
        dt = t_gps_s - t_ref
        if dt == 0.0:
            return st
        return SatStates(
            st.pos_ecef_m + st.vel_ecef_m_s * dt + 0.5 * acc * dt * dt,
            st.vel_ecef_m_s + acc * dt,
            st.clock_s + st.clock_drift_s_s * dt,
            st.clock_drift_s_s,
            st.valid,
        )

    def _atmosphere(
        self, t_gps_s: float, u_ned: np.ndarray, el: np.ndarray, h_m: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Klobuchar (L1) and Saastamoinen delays per satellite (all rows), recomputed every
        ``SKY_REFRESH_S`` or 5 m of height (they change by millimetres in that)."""
        c = self._atm_cache
        if c is None or abs(t_gps_s - c[0]) > SKY_REFRESH_S / 2 or abs(h_m - c[3]) > 5.0:
            up = el > 0
            az = np.arctan2(u_ned[:, 1], u_ned[:, 0]) % (2.0 * np.pi)
            e = np.maximum(el, 1e-3)
            klob = (
                klobuchar_m(*self.store.klobuchar, self.lat_rad, self.lon_rad, az, e, week_tow(t_gps_s)[1])
                if self.store.klobuchar is not None
                else np.zeros(len(el))
            )
            tropo = saastamoinen_m(self.lat_rad, self.home_alt_m + h_m, e)
            self._atm_cache = c = (t_gps_s, np.where(up, klob, 0.0), np.where(up, tropo, 0.0), h_m)
        return c[1], c[2]

    # -- one epoch ---------------------------------------------------------------------------------
    def observe(self, t_us: int, p_ned_m: np.ndarray, v_ned_m_s: np.ndarray) -> tuple[GnssEpoch, SatTruth]:
        """The epoch measured at boot time ``t_us`` by an antenna at ``p_ned_m`` moving at
        ``v_ned_m_s`` (mission frame): the receiver's report WITH the broadcast satellite states at
        transmission (what the receiver's own solution uses), and the truth per row."""
        cfg = self.cfg
        n_all = len(self.system)
        draws = self._noise.standard_normal(3 * n_all + 2)  # a fixed count per epoch (common random numbers)
        noise = draws[2:].reshape(3, n_all)
        recent = self._advance_clock(t_us, float(draws[0]), float(draws[1]))
        t = self.t0_gps_s + t_us * 1e-6
        r_ned_ecef = self.ecef_to_ned.T
        rx = self.home_ecef_m + r_ned_ecef @ p_ned_m
        v_rx = r_ned_ecef @ v_ned_m_s
        st = self._sky(t - T_LIGHT0_S)
        tau = (
            self._tau
        )  # from the previous epoch's light times (≤ 160 m of range ago): one pass leaves < 3 mm
        for _ in range(1 if recent else LIGHT_TIME_ITERATIONS):
            s = st.pos_ecef_m + st.vel_ecef_m_s * (T_LIGHT0_S - tau)[:, None]
            ang = OMEGA_E_RAD_S * tau
            c, sn = np.cos(ang), np.sin(ang)
            s_rot = np.column_stack((c * s[:, 0] + sn * s[:, 1], -sn * s[:, 0] + c * s[:, 1], s[:, 2]))
            d = s_rot - rx
            rho = np.sqrt(np.einsum("ij,ij->i", d, d))
            tau = rho / C_M_S
        self._tau = tau
        u = d / rho[:, None]
        u_ned = u @ self.ecef_to_ned.T
        el = np.arcsin(np.clip(-u_ned[:, 2], -1.0, 1.0))
        vis = st.valid & (el > math.radians(max(cfg.elevation_mask_deg, 0.05)))
        idx = np.flatnonzero(vis)
        el_v = el[idx]
        cos_el = np.cos(el_v)
        dir_ne = u_ned[idx, :2] / cos_el[:, None]
        tan_el = np.tan(el_v)
        sin_el = np.sin(el_v)
        h = -float(p_ned_m[2])
        p_ne = np.asarray(p_ned_m[:2], dtype=float)
        lam = self.wavelength_m[idx]
        m = len(idx)
        # direct path: clear, or diffracted over the dominant roof edge
        ray, (s_i, w_i, extra, cos_inc) = self.city.paths(p_ne, h, dir_ne, tan_el, WAVELENGTH_L1_M)
        blocked = ray.blocked
        if cfg.diffraction:
            amp_d = 10.0 ** (-knife_edge_loss_db(ray.nu) / 20.0)
            extra_d = np.where(
                blocked, diffraction_extra_m(ray.edge_distance_m, ray.edge_over_m, sin_el), 0.0
            )
        else:
            amp_d = np.where(blocked, 0.0, 1.0)
            extra_d = np.zeros(m)
        # strongest facade reflection per satellite
        amp_r = np.zeros(m)
        extra_r = np.zeros(m)
        dir_r = dir_ne.copy()
        if len(s_i):
            amp = self.facade_absorption[w_i] * reflection_amplitude(
                cos_inc, sin_el[s_i], self.facade_permittivity[w_i], cfg.antenna_xpd_db
            )
            order = np.lexsort((extra, -amp, s_i))
            first = np.r_[True, s_i[order][1:] != s_i[order][:-1]]
            best = order[first]
            sb, wb = s_i[best], w_i[best]
            amp_r[sb] = amp[best]
            extra_r[sb] = extra[best]
            axis = self.city.facades.axis[wb]
            dir_r[sb, axis] *= -1.0  # arrives from the mirrored direction
        # unmapped reflections: per blocked episode, from each satellite's own stream
        blk_all = np.zeros(n_all, dtype=bool)
        blk_all[idx] = blocked & (amp_r == 0.0)
        fresh = np.flatnonzero(blk_all & ~self._blocked)
        for i in fresh.tolist():
            g = self._episode_rngs[i]
            self._unmapped[i] = g.uniform() < cfg.unmapped_prob
            self._unmapped_delay_m[i] = g.exponential(cfg.unmapped_delay_mean_m)
            self._unmapped_phase[i] = g.uniform(0.0, 2.0 * math.pi)
        self._blocked = blk_all
        self._unmapped &= blk_all
        unm = self._unmapped[idx]
        extra_u = np.where(unm, self._unmapped_delay_m[idx], 0.0)
        loss_u = cfg.unmapped_loss_db + cfg.antenna_xpd_db * sin_el
        if cfg.unmapped_spreading_ref_m > 0.0:
            loss_u = loss_u + spreading_loss_db(extra_u, cfg.unmapped_spreading_ref_m)
        amp_u = np.where(unm, 10.0 ** (-loss_u / 20.0), 0.0)
        # components: 0 direct, 1 facade reflection, 2 unmapped; track the strongest
        amps = np.column_stack((amp_d, amp_r, amp_u))
        extras = np.column_stack((extra_d, extra_r, extra_u))
        order = np.argsort(-amps, axis=1, kind="stable")
        rows = np.arange(m)
        k1, k2 = order[:, 0], order[:, 1]
        a1, a2 = amps[rows, k1], amps[rows, k2]
        e1, e2 = extras[rows, k1], extras[rows, k2]
        alpha = np.where(a1 > 0, a2 / np.where(a1 > 0, a1, 1.0), 0.0)
        delta_m = e2 - e1
        phase = 2.0 * np.pi * delta_m / lam + np.where((k1 == 0) != (k2 == 0), np.pi, 0.0)
        phase = (
            phase
            + np.where(k2 == 2, self._unmapped_phase[idx], 0.0)
            - np.where(k1 == 2, self._unmapped_phase[idx], 0.0)
        )
        chip = self.chip_m[idx]
        delta_chips = delta_m / chip
        corr = np.maximum(1.0 - np.abs(delta_chips), 0.0)
        cos_ph = np.cos(phase)
        ac = alpha * corr
        comb2 = 1.0 + 2.0 * ac * cos_ph + ac * ac  # |1 + α R(δ) e^{iθ}|²
        diffuse_err_m = np.zeros(m)
        if cfg.diffuse_fading:
            g_d = self._diffuse(t_us)[idx] * 10.0 ** (
                -np.where(k1 == 0, cfg.diffuse_k_los_db, cfg.diffuse_k_nlos_db) / 20.0
            )
            dd = self._fade_delay_m[idx] / chip
            comb = 1.0 + ac * np.exp(1j * phase) + g_d * np.maximum(1.0 - dd, 0.0)
            comb2 = np.abs(comb) ** 2  # |1 + α R(δ) e^{iθ} + g R(δ_d)|²
            diffuse_err_m = chip * dll_multipath_chips(
                np.clip(g_d.real, -0.99, 0.99), dd, cfg.correlator_spacing_chips
            )
        with np.errstate(divide="ignore"):
            cn0 = (
                unobstructed_cn0_dbhz(el_v, self.system[idx], cfg)
                + 10.0 * np.log10(a1 * a1 * np.maximum(comb2, 1e-12))
                + cfg.cn0_noise_db * noise[0, idx]
            )
        # tracking with hysteresis: a signal is acquired at cn0_acquire_dbhz, then kept down to the threshold
        was = self._lock_start_us[idx] >= 0
        track = (a1 > 0) & (cn0 >= np.where(was, cfg.cn0_threshold_dbhz, cfg.cn0_acquire_dbhz))
        a_inph = alpha * cos_ph
        env = e1 + chip * dll_multipath_chips(
            np.clip(a_inph, -0.99, 0.99), delta_chips, cfg.correlator_spacing_chips
        ) + diffuse_err_m  # (the two multipath errors superposed: small amplitudes)
        cn0_seen = np.maximum(cn0, 0.0)  # (−inf where nothing arrives: those rows are not reported)
        sig = dll_sigma_m(cn0_seen, chip, cfg)
        n_code = sig * noise[1, idx]
        # shared errors: atmosphere, orbits/clocks, inter-frequency biases
        az = np.arctan2(u_ned[idx, 1], u_ned[idx, 0]) % (2.0 * np.pi)
        klob_all, tropo_all = self._atmosphere(t, u_ned, el, h)
        klob, tropo = klob_all[idx], tropo_all[idx]
        iono = klob * self.iono_scale[idx] * self.iono_factor[idx]
        common = (
            self.sisre_m[idx] + (self.iono_factor[idx] - 1.0) * klob * self.iono_scale[idx] + self.ifb_m[idx]
        )
        isb = self.isb_all_m[idx]
        clk_sv = st.clock_s[idx] + st.clock_drift_s_s[idx] * (T_LIGHT0_S - tau[idx])
        b_m = C_M_S * self.clock_bias_s
        pr = (
            rho[idx]
            + b_m
            + isb
            - C_M_S * clk_sv
            + iono
            + tropo
            + self.sisre_m[idx]
            + self.ifb_m[idx]
            + env
            + n_code
        )
        # pseudorange rate: the tracked path's range rate (a reflection arrives from the mirrored direction)
        vs = st.vel_ecef_m_s[idx]
        ang = OMEGA_E_RAD_S * tau[idx]
        c, sn = np.cos(ang), np.sin(ang)
        vs_rot = np.column_stack((c * vs[:, 0] + sn * vs[:, 1], -sn * vs[:, 0] + c * vs[:, 1], vs[:, 2]))
        uu = u[idx]
        sat_rate = np.einsum("ij,ij->i", uu, vs_rot)
        dir_arr = np.where((k1 == 1)[:, None], dir_r, dir_ne)
        arr_ecef = np.column_stack((dir_arr * cos_el[:, None], -sin_el)) @ self.ecef_to_ned
        rx_rate = arr_ecef @ v_rx
        geo_rate = sat_rate - uu @ v_rx
        tau_dot = geo_rate / C_M_S
        s_r = s_rot[idx]
        rot_rate = OMEGA_E_RAD_S * tau_dot * (uu[:, 0] * s_r[:, 1] - uu[:, 1] * s_r[:, 0])
        rate = (
            sat_rate * (1.0 - tau_dot)
            + rot_rate
            - rx_rate
            + C_M_S * (self.clock_drift_s_s - st.clock_drift_s_s[idx])
            + cfg.doppler_sigma_m_s * 10.0 ** ((CN0_REF_DBHZ - cn0_seen) / 20.0) * noise[2, idx]
        )
        # lock times
        tracked_all = np.zeros(n_all, dtype=bool)
        tracked_all[idx[track]] = True
        self._lock_start_us = np.where(
            tracked_all, np.where(self._lock_start_us < 0, t_us, self._lock_start_us), -1
        )
        keep = track
        rows_all = idx[keep]
        self.lock_ms = (t_us - self._lock_start_us[rows_all]) / 1e3
        sat_pos = s[idx][keep]  # at transmission, in the transmission-time frame
        ep = make_epoch(
            t + self.clock_bias_s,
            self.system[rows_all],
            self.prn[rows_all],
            pr[keep],
            pseudorange_var_m2=(0.01 * 2.0 ** prstd_index(sig[keep])) ** 2,
            pseudorange_rate_m_s=rate[keep],
            cn0_dbhz=np.clip(np.rint(cn0[keep]), 0, 255),
            elevation_deg=np.rint(np.degrees(el_v[keep])),
            azimuth_deg=np.rint(np.degrees(az[keep])) % 360,
            sat_pos_ecef_m=sat_pos,
            sat_vel_ecef_m_s=vs[keep],
            sat_clock_s=clk_sv[keep],
            sat_clock_drift_s_s=st.clock_drift_s_s[idx][keep],
        )
        truth = SatTruth(
            los=~blocked[keep],
            nlos=(k1 != 0)[keep],
            env_error_m=env[keep],
            noise_m=n_code[keep],
            common_error_m=common[keep],
            range_m=rho[idx][keep],
            extra_path_m=e1[keep],
            model_atmosphere_m=(klob * self.iono_scale[idx] + tropo)[keep],
        )
        return ep, truth
