"""One mission profile flown by ArduCopter SITL on our degraded GNSS, end to end.

``fly_ardupilot(options)``: plan the route (A*, minimum jerk), start ArduCopter SITL at the
profile's start point (``--home``; its EKF origin is read back from GPS_GLOBAL_ORIGIN), run the
session (GNSS source + flight driver) until the goal is reached or time runs out, then evaluate
EKF3 and every companion method on the recorded samples. Closed loop (``--feed gps-input|vision``):
the companion runs as its own process beside the SITL (``companion_process``), on SERIAL1, and
what it sent ArduPilot is scored too (row ``companion-live``). Returns ``fly``'s ``FlightResult`` (the
same summary keys and series, plus the EKF3 and per-method figures) for ``write_outputs``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.statistics import describe
from companion.errors import UserError
from companion.estimator import METHODS, EstimatorConfig, check_method
from companion.mission import load_mission
from simvehicle.config import sim_config_for
from simvehicle.gnss import NedToGeodetic
from simvehicle.harness.ardupilot.analysis import (
    AUTOPILOT_ROW,
    LIVE_ROW,
    Track,
    autopilot_track,
    companion_track,
    count_collisions,
    errors,
    interpolated_track,
)
from simvehicle.harness.ardupilot.companion_process import (
    CompanionProcess,
    companion_command,
    read_summary,
    sent_track,
)
from simvehicle.harness.ardupilot.config import FEEDS, GPS1_ID, GPS2_ID, ArduPilotConfig, ardupilot_parameters
from simvehicle.harness.ardupilot.driver import FlightDriver
from simvehicle.harness.ardupilot.gnss_source import UrbanGnssSource
from simvehicle.harness.ardupilot.session import ArduPilotSession, Recording
from simvehicle.harness.ardupilot.sitl import ArduPilotSitl, SitlConfig
from simvehicle.harness.backend import FlightResult
from simvehicle.harness.fly import planned_route

VELOCITY_SEED_STREAM = 1  # velocity noise: default_rng([seed, this]); positions: default_rng(seed)
HORIZONTAL_ERROR_PREFIX = "est_error_h_m:"  # series keys of every row's horizontal error (not in the CSV)
INSTANCE_RANGE = (20, 40)  # -I 20..39: this tool's instances (ports 5960..6153)


@dataclass(frozen=True)
class ArduPilotFlightOptions:
    mission: str
    profile: int
    method: str
    seed: int
    out_dir: Path
    feed: str = "none"
    config: ArduPilotConfig = field(default_factory=ArduPilotConfig)
    instance_range: tuple[int, int] = INSTANCE_RANGE
    methods: tuple[str, ...] = METHODS  # every companion method evaluated on the same samples
    # The filter's defaults are those of real sensors (the quad106 log). A mission's ``estimator:``
    # section describes OUR simulated IMU (0.006 m/s² noise, true attitude), not ArduPilot's, so it
    # is not used here; nothing was tuned on ArduPilot flights.
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)


def fly_ardupilot(opts: ArduPilotFlightOptions) -> FlightResult:
    cfg = opts.config
    try:
        cfg.validate()
    except ValueError as exc:
        raise UserError(f"ardupilot: {exc}") from None
    if opts.feed not in FEEDS:
        raise UserError(f"--feed {opts.feed}: with --vehicle ardupilot, --feed is one of {', '.join(FEEDS)}")
    check_method(opts.method)
    m = load_mission(opts.mission)
    if not 0 <= opts.profile < len(m.profiles):
        raise UserError(f"--profile {opts.profile}: mission {m.name!r} has profiles 0..{len(m.profiles) - 1}")
    route = planned_route(m, opts.profile, 0.0)
    sim = sim_config_for(m)
    start_ned = np.array([*m.profiles[opts.profile].start_ne_m, 0.0])
    lat, lon, alt = NedToGeodetic(m.frame)(start_ned)
    closed = opts.feed != "none"
    # open loop: EKF3 gets the Doppler velocity (unless switched off); closed loop: the companion
    # (which fuses no GNSS velocity) reads the raw fixes, so they carry the same velocity for the record
    sigma = cfg.gnss_velocity_sigma_m_s if cfg.gnss_velocity or closed else None
    source = UrbanGnssSource(sim.gnss, m.world, m.frame, cfg.gnss_rate_hz, np.random.default_rng(opts.seed),
                             float(m.world.clearance_m(*start_ned[:2])), sigma,
                             np.random.default_rng([opts.seed, VELOCITY_SEED_STREAM]))
    driver = FlightDriver(cfg, route, m.altitude_m)
    opts.out_dir.mkdir(parents=True, exist_ok=True)
    params = ardupilot_parameters(cfg, opts.feed)
    sitl_cfg = SitlConfig(work_dir=opts.out_dir / "ardupilot", home=(lat, lon, alt, 0.0), speedup=cfg.speedup,
                          params=params, instance_range=opts.instance_range)
    companion_dir = opts.out_dir / "companion"
    companion_rc: int | None = None
    cmd: list[str] = []
    wall0, cpu0 = time.perf_counter(), time.process_time()
    with ArduPilotSitl(sitl_cfg) as sitl:
        session = ArduPilotSession(sitl.ports[0], cfg, m.frame, source, driver, opts.out_dir / "run.tlog",
                                   GPS2_ID if closed else GPS1_ID)
        companion: CompanionProcess | None = None
        try:
            session.connect(sitl.running)
            if closed:  # SERIAL1 listens once SERIAL0 has its client
                cmd = companion_command(sitl.wait_serial(1), companion_dir, opts.feed, opts.method,
                                        (lat, lon, alt))
                companion = CompanionProcess(cmd, companion_dir / "companion.log").start()
            ended_by = session.run(_alive(sitl, companion))
            if companion is not None and not companion.running() and ended_by == "sitl_exited":
                ended_by = "companion_exited"
        finally:
            if companion is not None:
                companion_rc = companion.stop()
            session.close()
        instance = sitl.instance
    wall_s, cpu_s = time.perf_counter() - wall0, time.process_time() - cpu0
    rec = session.rec
    sim_s = (rec.imu_t_us[-1] - rec.imu_t_us[0]) * 1e-6 if rec.imu_t_us else 0.0
    run_info = {
        "instance": instance, "speedup": cfg.speedup, "feed": opts.feed, "ended_by": ended_by,
        "parameters": params,
        "gnss_velocity": None if sigma is None else f"truth + N(0, {sigma:g} m/s) per axis",
        "phase_times_s": {k: v * 1e-6 for k, v in driver.phase_times_us.items()},
        "sim_s": sim_s, "wall_s": wall_s, "session_cpu_s": cpu_s,
        "sim_s_per_wall_s": sim_s / wall_s if wall_s > 0 else math.nan,
        "messages_received": rec.counts, "rejected": rec.rejected,
        "gps_input_sent": session.gps_sent, "setpoints_sent": session.setpoints_sent,
        # extra delay (ArduPilot time) of everything we send, from the scheduler: GPS_INPUT reaches
        # EKF3 this much later than the model's latency says (the companion's fixes do not have it)
        "command_delay_ms": (delay := _delay_stats(session.command_delay_us)),
        # closed loop: the companion's estimates reach ArduPilot this late (its process's lag)
        "feed_delay_ms": (feed_delay := _delay_stats(session.feed_delay_us)),
        "valid": bool(delay["p95"] <= cfg.max_command_delay_ms
                      and (not closed or feed_delay["p95"] <= cfg.max_command_delay_ms)),
        "statustext": [f"{t * 1e-6:.1f} s {s}" for t, s in rec.statustext[-40:]],
    }
    live = None
    if closed:
        summary = read_summary(companion_dir)
        run_info["companion"] = {"command": " ".join(cmd[1:]), "exit_code": companion_rc,
                                 "node": summary.get("node"), "samples": summary.get("samples"),
                                 "gnss_delay": summary.get("gnss_delay"), "problems": summary.get("problems")}
        live = sent_track(companion_dir / "run.tlog", opts.feed, LocalNedFrame(lat, lon, alt), m.frame)
    return evaluate_flight(opts, m, route, rec, source, driver, run_info, sim.vehicle.radius_m, live)


def _alive(sitl: ArduPilotSitl, companion: CompanionProcess | None) -> Any:
    return lambda: sitl.running() and (companion is None or companion.running())


def _delay_stats(delays_us: list[int]) -> dict[str, float]:
    return describe(np.asarray(delays_us, dtype=float) * 1e-3, ("median", "p95", "max", "n"))


def evaluate_flight(opts: ArduPilotFlightOptions, mission: Any, route: Any, rec: Recording,
                    source: UrbanGnssSource, driver: FlightDriver, run_info: dict[str, Any],
                    radius_m: float, live: tuple[np.ndarray, np.ndarray] | None = None) -> FlightResult:
    """Score every row at the route phase's truth samples. ``live`` (closed loop): what the companion
    process sent ArduPilot; it becomes row ``companion-live`` and the flight's ``estimation_error_m``."""
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
    tracks[AUTOPILOT_ROW] = autopilot_track(rec, times_us)
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
    if live is not None:  # what ArduPilot got; bias, β and NIS from the replay of the same method
        mine = Track(tracks[LIVE_ROW].p_ned_m, mine.b_ned_m, mine.beta, mine.nis, mine.counters)
    ekf = tracks[AUTOPILOT_ROW]
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
    summary: dict[str, Any] = {
        "mission": mission.name, "profile": opts.profile, "method": opts.method, "seed": opts.seed,
        "vehicle": "ardupilot", "feed": opts.feed,
        "reached_goal": driver.outcome == "reached_goal",
        "valid": run_info["valid"],  # False: our commands reached ArduPilot late (a loaded machine)
        "collisions": count_collisions(clearance, radius_m),
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
        "ardupilot": run_info,
    }
    return FlightResult(summary, series if t_s.size else {}, route)
