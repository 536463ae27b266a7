"""The raw receiver as the vehicle's GNSS: measurement epochs, their single-point fixes, delivery.

``RawGnssModel`` offers what ``SimVehicle`` asks of ``simvehicle.gnss.GnssModel`` (``sample``,
``release``, ``next_release_us``, ``to_fix``, accuracies, ``bias_ned_m``, ``latency_s``, ``sent``),
so the rest of the vehicle (fixes in ``StepOutput.gnss_ned``/``gnss``, GPS_RAW_INT in SITL) is
unchanged; in addition each epoch's raw observations come out through :meth:`drain_raw`
(``StepOutput.gnss_raw``).

One epoch per ``1 / rate_hz`` at the control-period ends that are multiples of it, measured at the
TRUE position and velocity (:class:`simvehicle.receiver.Receiver`); the receiver solves it at once
(``companion.gnss.solve_position``: the broadcast satellite states at transmission, Klobuchar,
Saastamoinen, the configured weighting, from its previous solution moved on by its velocity) and
releases the raw epoch and its fix together ``latency_s`` later (an epoch without a solution
releases no fix). The fix is valid at the measurement's true time; ``bias_ned_m`` (the truth's
``gnss_bias_ned_m``) is the latest fix's error.

The sky: GPS time of boot ``t0`` = ``start_utc`` + a whole number of seconds drawn from the seed in
``[0, start_spread_s)``; the broadcast ephemerides (``store``, :mod:`simvehicle.constellation`)
cover boot − 15 min … boot + 1 h and are extended (by another hour) when a flight lasts longer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix
from companion.errors import ConfigError
from companion.gnss.constants import C_M_S
from companion.gnss.geometry import ecef_to_ned_matrix, geodetic_to_ecef
from companion.gnss.spp import SppConfig, SppSolution, preload_chi2, solve_position
from companion.gnss.timescale import gps_from_calendar
from companion.mission.city3d import City
from simvehicle.config import ReceiverConfig, parse_utc
from simvehicle.constellation import SYSTEM_NAMES, ephemeris_store
from simvehicle.gnss import FIX_TYPE_3D, NedFix, NedToGeodetic, QueuedDelivery, ReleaseQueue
from simvehicle.receiver import RawObservation, Receiver

SPAN_BEFORE_S = 900.0
SPAN_AFTER_S = 3600.0
_NAN3 = np.full(3, np.nan)


@dataclass(frozen=True, slots=True)
class RawFix(NedFix):
    """A single-point fix: ``sigma_noise_m`` its reported horizontal 1σ per axis, ``v_ned_m_s`` /
    ``sigma_velocity_m_s`` the solution's Doppler velocity and its 1σ per axis."""

    v_acc_m: float = math.nan
    hdop: float = math.nan


def boot_gps_time_s(cfg: ReceiverConfig, rng: np.random.Generator) -> float:
    """GPS time at vehicle boot: ``start_utc`` plus whole seconds drawn in ``[0, start_spread_s)``."""
    t = gps_from_calendar(*parse_utc(cfg.start_utc), "UTC")
    return t + (math.floor(rng.uniform(0.0, cfg.start_spread_s)) if cfg.start_spread_s > 0 else 0.0)


class RawGnssModel(QueuedDelivery[tuple[RawObservation, RawFix | None]]):
    """Receiver epochs and fixes, queued and released after the receiver's latency (seeded)."""

    def __init__(
        self,
        cfg: ReceiverConfig,
        rects_m: np.ndarray,
        heights_m: np.ndarray,
        frame: LocalNedFrame,
        rng: np.random.Generator,
        control_period_us: int,
    ) -> None:
        self.cfg = cfg
        self.period_us = round(1e6 / cfg.rate_hz)
        if self.period_us % control_period_us:
            raise ConfigError(
                f"receiver rate_hz {cfg.rate_hz}: its period must be a multiple of the control "
                f"period ({control_period_us} µs)"
            )
        self.frame = frame
        self.to_geodetic = NedToGeodetic(frame)
        self.systems = tuple(SYSTEM_NAMES[s] for s in cfg.systems)
        self.t0_gps_s = boot_gps_time_s(cfg, rng)
        self._covered_to_s = self.t0_gps_s + SPAN_AFTER_S
        self.store = ephemeris_store(self.t0_gps_s - SPAN_BEFORE_S, self._covered_to_s, self.systems)
        self.receiver = Receiver(cfg, City(rects_m, heights_m), frame, self.store, self.t0_gps_s, rng)
        self.spp = SppConfig(weighting=cfg.weighting, raim=cfg.raim)
        preload_chi2()
        lat, lon = math.radians(frame.home_lat_deg), math.radians(frame.home_lon_deg)
        self._home_ecef = geodetic_to_ecef(lat, lon, frame.home_alt_m)
        self._to_ned = ecef_to_ned_matrix(lat, lon)
        self._latency_us = math.ceil(cfg.latency_s * 1e6 - 1e-6)
        self._queue: ReleaseQueue[tuple[RawObservation, RawFix | None]] = ReleaseQueue()
        self._released: list[RawObservation] = []
        self._prev: tuple[int, np.ndarray, np.ndarray] | None = (
            None  # the last solution: time, position, velocity
        )
        self._resets = 0
        self.bias_ned_m = np.zeros(3)
        self.latency_s = cfg.latency_s
        self.sent = 0  # fixes made
        self.epochs = 0  # epochs measured
        self.unsolved = 0  # epochs without a fix

    @property
    def klobuchar(self) -> tuple[np.ndarray, np.ndarray] | None:
        return self.store.klobuchar

    def _extend(self, t_gps_s: float) -> None:
        """Broadcast ephemerides for a flight that outlasts them."""
        self._covered_to_s = t_gps_s + SPAN_AFTER_S
        self.store = ephemeris_store(t_gps_s - SPAN_BEFORE_S, self._covered_to_s, self.systems)
        self.receiver.store = self.store

    def sample(
        self, t_us: int, p_ned_m: np.ndarray, clearance_m: float, v_ned_m_s: np.ndarray | None = None
    ) -> RawFix | None:
        """At an epoch time, measure, solve and queue (epoch and fix); otherwise nothing."""
        if t_us % self.period_us:
            return None
        return self.measure(t_us, p_ned_m, v_ned_m_s)

    def measure(self, t_us: int, p_ned_m: np.ndarray, v_ned_m_s: np.ndarray | None = None) -> RawFix | None:
        """One epoch at ``t_us`` (whatever the grid: a harness driven by another simulator's truth
        measures when its truth arrives), solved and queued; its fix, or None without a solution."""
        t_gps = self.t0_gps_s + t_us * 1e-6
        if t_gps > self._covered_to_s - 600.0:
            self._extend(t_gps)
        v = np.zeros(3) if v_ned_m_s is None else np.asarray(v_ned_m_s, dtype=float)
        rx = self.receiver
        ep, truth = rx.observe(t_us, np.asarray(p_ned_m, dtype=float), v)
        # the receiver removes the satellite clocks and the broadcast atmosphere (Klobuchar, Saastamoinen:
        # evaluated here at the true antenna, which its own estimate differs from by micro-radians of
        # elevation) and solves the corrected pseudoranges
        corrected = ep.replace(
            pseudorange_m=ep.pseudorange_m + C_M_S * ep.sat_clock_s - truth.model_atmosphere_m,
            pseudorange_rate_m_s=ep.pseudorange_rate_m_s + C_M_S * ep.sat_clock_drift_s_s,
            corrected=True,
        )
        sol = solve_position(corrected, self.spp, p0_ecef_m=self._guess_ecef(t_us))
        self.epochs += 1
        nan = np.full(ep.n, np.nan)
        report = ep.replace(
            sat_pos_ecef_m=np.full((ep.n, 3), np.nan),
            sat_vel_ecef_m_s=np.full((ep.n, 3), np.nan),
            sat_clock_s=nan,
            sat_clock_drift_s_s=nan,
        )
        raw = RawObservation(
            int(t_us),
            -1,
            report,
            truth,
            t_gps,
            rx.clock_bias_s,
            rx.clock_drift_s_s,
            sol if sol.ok else None,
            rx.lock_ms.copy(),
            rx.clock_resets > self._resets,
        )
        self._resets = rx.clock_resets
        fix = None
        if sol.ok:
            self._prev = (int(t_us), sol.p_ecef_m, sol.v_ecef_m_s)
            fix = self._fix(int(t_us), sol)
            self.bias_ned_m = fix.p_ned_m - np.asarray(p_ned_m, dtype=float)
            self.sent += 1
        else:
            self.unsolved += 1
        self._queue.put(int(t_us) + self._latency_us, (raw, fix))
        return fix

    def _guess_ecef(self, t_us: int) -> np.ndarray | None:
        """Where the receiver starts its iterations: its last solution moved on by its Doppler velocity."""
        if self._prev is None:
            return None
        t0, p, v = self._prev
        return p + v * (t_us - t0) * 1e-6 if np.isfinite(v).all() else p

    def to_ned_m(self, p_ecef_m: np.ndarray) -> np.ndarray:
        """An ECEF position in the mission's NED frame (the same map as ``LocalNedFrame``)."""
        return self._to_ned @ (np.asarray(p_ecef_m, dtype=float) - self._home_ecef)

    def _fix(self, t_us: int, sol: SppSolution) -> RawFix:
        p_ned = self.to_ned_m(sol.p_ecef_m)
        v = sol.v_ecef_m_s
        v_ned = self._to_ned @ v if np.isfinite(v).all() else None
        return RawFix(t_us, p_ned, sol.h_acc_m, sol.n_used, v_ned_m_s=v_ned,
                      sigma_velocity_m_s=sol.vel_acc_m_s, v_acc_m=sol.v_acc_m, hdop=sol.dops.hdop)

    def release(self, t_us: int) -> list[RawFix]:
        """Fixes due by ``t_us`` (their raw epochs go to :meth:`drain_raw`, stamped with ``t_us``)."""
        out: list[RawFix] = []
        for raw, fix in self._queue.due(t_us):
            self._released.append(replace(raw, arrival_us=int(t_us)))
            if fix is not None:
                out.append(fix)
        return out

    def drain_raw(self) -> list[RawObservation]:
        """The raw epochs released since the last call, in release order."""
        out, self._released = self._released, []
        return out

    def reported_accuracy_m(self, fix: NedFix) -> float:
        """The fix's reported horizontal 1σ per axis (the solution's a-posteriori covariance)."""
        return fix.sigma_noise_m

    def reported_accuracies_m(self, fix: NedFix) -> tuple[float, float]:
        """(horizontal per axis, vertical) 1σ the receiver reports."""
        return fix.sigma_noise_m, fix.v_acc_m if isinstance(fix, RawFix) else fix.sigma_noise_m

    def reported_velocity_accuracy_m_s(self, fix: NedFix) -> float:
        """The fix's reported 1σ speed accuracy per axis (NaN without a Doppler velocity)."""
        return fix.sigma_velocity_m_s if isinstance(fix, RawFix) else math.nan

    def to_fix(self, fix: NedFix) -> GnssFix:
        """The wire form: geodetic position, accuracies, HDOP and the Doppler velocity."""
        lat, lon, alt = self.to_geodetic(fix.p_ned_m)
        raw = fix if isinstance(fix, RawFix) else None
        v = None if raw is None else raw.v_ned_m_s
        v_acc, hdop = (raw.v_acc_m, raw.hdop) if raw else (math.nan, math.nan)
        return GnssFix(
            fix.t_validity_us, lat, lon, alt, FIX_TYPE_3D, fix.satellites, fix.sigma_noise_m, v_acc, hdop, v,
            vel_acc_m_s=raw.sigma_velocity_m_s if raw else math.nan,
        )
