"""A flight beside a foreign autopilot, scored: every companion method, the autopilot's EKF, truth.

``score_flight(...)`` takes what the session recorded (``Recording``), the fixes it sent and how
the flight went, runs every companion method on the same samples (``analysis``) and returns
``fly``'s ``FlightResult``: the same summary keys and series as ``beliefnav fly`` (``reached_goal``,
``collisions``, ``estimation_error_m``, ``tracking_error_m``, ...) plus the autopilot's
(``autopilot_estimation_error_m``, its horizontal variants, ``methods`` = every row, and the
vehicle's own section, e.g. ``ardupilot`` or ``px4``, with how the run went).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.domain.statistics import describe
from companion.mission import Mission
from companion.planning import Route
from simvehicle.harness.backend import FlightResult
from simvehicle.harness.foreign.analysis import (
    LIVE_ROW,
    SPP_ROW,
    TIGHT_PREFIX,
    Track,
    autopilot_track,
    companion_track,
    count_collisions,
    errors,
    held_track,
    interpolated_track,
    tight_track,
)
from simvehicle.harness.foreign.canyon_source import CanyonGnssSource
from simvehicle.harness.foreign.config import ForeignFlightOptions
from simvehicle.harness.foreign.driver import RouteDriver
from simvehicle.harness.foreign.gnss_source import GnssSource
from simvehicle.harness.foreign.recording import Recording

HORIZONTAL_ERROR_PREFIX = "est_error_h_m:"  # series keys of every row's horizontal error (not in the CSV)


@dataclass(frozen=True)
class Vehicle:
    """How a foreign autopilot's flights are named: backend name (the summary's ``vehicle`` and the
    key of its run section) and the row of its own estimator."""

    name: str  # "ardupilot", "px4"
    autopilot_row: str  # "ardupilot-ekf3", "px4-ekf2"


def delay_stats(delays_us: list[int]) -> dict[str, float]:
    """Median, p95, max (ms) and count of delays given in µs."""
    return describe(np.asarray(delays_us, dtype=float) * 1e-3, ("median", "p95", "max", "n"))


def raw_tracks(source: CanyonGnssSource, mission: Mission, times_us: np.ndarray, weightings: tuple[str, ...],
               rec: Recording) -> dict[str, Track]:
    """Row ``spp`` (the receiver's fixes as they arrived) and ``tight-<weighting>`` for each weighting."""
    sent = source.sent
    out = {SPP_ROW: held_track(np.array([sf.arrival_us for sf in sent], dtype=np.int64),
                               np.array([sf.p_ned_m for sf in sent]), times_us)}
    for w in weightings:
        out[f"{TIGHT_PREFIX}{w}"] = tight_track(rec, source.raw, w, source.model.store, mission, times_us)
    return out


def score_flight(vehicle: Vehicle, opts: ForeignFlightOptions, mission: Mission, route: Route, rec: Recording,
                 source: GnssSource, driver: RouteDriver, run_info: dict[str, Any], radius_m: float,
                 live: tuple[np.ndarray, np.ndarray] | None = None) -> FlightResult:
    """Score every row at the route phase's truth samples. ``live`` (closed loop): what the companion
    process sent the autopilot; it becomes row ``companion-live`` and the flight's ``estimation_error_m``."""
    t_all = np.asarray(rec.truth_t_us, dtype=np.int64)
    t0 = driver.route_t0_us
    sel = t_all >= t0 if t0 is not None else np.zeros(len(t_all), dtype=bool)
    times_us = t_all[sel]
    p_true = np.asarray(rec.truth_p_ned_m).reshape(-1, 3)[sel]
    clearance = np.asarray(rec.truth_clearance_m)[sel]
    t_s = (times_us - (t0 or 0)) * 1e-6
    p_ref = route.reference(t_s)[0] if t_s.size else np.zeros((0, 3))
    tracks = {name: companion_track(rec, source.sent, name, opts.estimator, mission, times_us)
              for name in dict.fromkeys((opts.method, *opts.methods))}
    tracks[vehicle.autopilot_row] = autopilot_track(rec, times_us)
    if isinstance(source, CanyonGnssSource):  # the raw epochs: the receiver's fixes and the tight rows
        tracks.update(raw_tracks(source, mission, times_us, opts.tight_methods, rec))
    if live is not None:
        tracks[LIVE_ROW] = interpolated_track(*live, times_us)
    per_method = {}
    method_errors: dict[str, np.ndarray] = {}  # horizontal error per sample, for campaigns
    for name, tr in tracks.items():
        e3, eh = errors(tr.p_ned_m, p_true)
        per_method[name] = {"estimation_error_m": describe(e3),
                            "estimation_error_horizontal_m": describe(eh)}
        method_errors[name] = eh
    mine: Track = tracks[opts.method]
    if live is not None:  # what the autopilot got; bias, β and NIS from the replay of the same method
        mine = Track(tracks[LIVE_ROW].p_ned_m, mine.b_ned_m, mine.beta, mine.nis, mine.counters)
    ekf = tracks[vehicle.autopilot_row]
    e3, eh = errors(mine.p_ned_m, p_true)
    a3, ah = errors(ekf.p_ned_m, p_true)
    track_err = np.linalg.norm(p_true - p_ref, axis=1)
    series = {
        "t_s": t_s, "p_true_ned_m": p_true, "p_est_ned_m": mine.p_ned_m, "p_ref_ned_m": p_ref,
        "b_true_ned_m": np.asarray(rec.truth_bias_ned_m).reshape(-1, 3)[sel], "b_est_ned_m": mine.b_ned_m,
        "beta": mine.beta, "nis": mine.nis, "latency_s": np.asarray(rec.truth_latency_s)[sel],
        "clearance_m": clearance, "est_error_m": e3, "track_error_m": track_err,
        "p_autopilot_ned_m": ekf.p_ned_m, "autopilot_error_m": a3,
        **{f"{HORIZONTAL_ERROR_PREFIX}{name}": e for name, e in method_errors.items()},
    }
    nav = mine.counters
    collisions = count_collisions(clearance, radius_m)
    summary: dict[str, Any] = {
        "mission": mission.name, "profile": opts.profile, "method": opts.method, "seed": opts.seed,
        "vehicle": vehicle.name, "feed": opts.feed,
        # as fly's: never after a contact (SITL has no buildings, so the flight went on; ended_by
        # keeps the driver's own outcome)
        "reached_goal": driver.outcome == "reached_goal" and collisions == 0,
        "valid": run_info["valid"],  # False: our commands reached the autopilot late (a loaded machine)
        "collisions": collisions,
        "duration_s": float(t_s[-1]) if t_s.size else 0.0,
        "route_duration_s": route.duration_s,
        "wall_s": run_info["wall_s"],
        "estimation_error_m": describe(e3),
        "estimation_error_horizontal_m": describe(eh),
        "autopilot_estimation_error_m": describe(a3),
        "autopilot_estimation_error_horizontal_m": describe(ah),
        "tracking_error_m": describe(track_err),
        "min_clearance_m": float(np.min(clearance)) if clearance.size else math.nan,
        "methods": per_method,
        "gnss": {"sent": len(source.sent), "fused": int(nav.get("gnss_fused", 0)),
                 "rejected": int(sum(v for k, v in nav.items() if k.startswith("gnss_rejected")))},
        "estimator_counters": nav,
        vehicle.name: run_info,
    }
    return FlightResult(summary, series if t_s.size else {}, route)
