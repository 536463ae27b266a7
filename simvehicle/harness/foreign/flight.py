"""What every foreign-autopilot flight does before and after its session.

``plan_flight``: the options checked (one-line errors), the route planned (A*, minimum jerk), the
SITL's home (the profile's start point, on the ground), our GNSS source seeded from the flight's
seed. ``run_info``: how the session went (phases, simulated and wall time, messages, command and
feed delays, validity). ``companion_info``: the closed loop's companion process, and what it sent
(row ``companion-live``).
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.errors import UserError
from companion.estimator import check_method
from companion.mission import Mission, load_mission
from companion.planning import Route
from simvehicle.config import SimConfig, sim_config_for
from simvehicle.gnss import NedToGeodetic
from simvehicle.harness.fly import planned_route
from simvehicle.harness.foreign.canyon_source import CanyonGnssSource
from simvehicle.harness.foreign.companion_process import CompanionProcess, read_summary, sent_track
from simvehicle.harness.foreign.config import ForeignFlightConfig, ForeignFlightOptions
from simvehicle.harness.foreign.gnss_source import VELOCITY_SEED_STREAM, UrbanGnssSource
from simvehicle.harness.foreign.scoring import delay_stats
from simvehicle.harness.foreign.session import ForeignSession
from simvehicle.ubx_server import ReceiverStream

FOREIGN_SCENARIOS = ("paper", "canyon")  # the scenarios whose GNSS a foreign autopilot is flown on


@dataclass(frozen=True)
class FlightPlan:
    mission: Mission
    route: Route
    sim: SimConfig
    home: tuple[float, float, float]  # the SITL's home: the profile's start on the ground (deg, deg, m)
    closed: bool  # the autopilot flies on the companion process's feed
    velocity_sigma_m_s: float | None  # the raw fixes' Doppler velocity noise (None: none, or the receiver's)
    source: UrbanGnssSource | CanyonGnssSource

    @property
    def canyon(self) -> CanyonGnssSource | None:
        """The calibrated raw receiver (scenario ``canyon``), None for our eq. 22-27 fixes."""
        return self.source if isinstance(self.source, CanyonGnssSource) else None


def plan_flight(vehicle: str, opts: ForeignFlightOptions, cfg: ForeignFlightConfig,
                feeds: tuple[str, ...]) -> FlightPlan:
    try:
        cfg.validate()
    except ValueError as exc:
        raise UserError(f"{vehicle}: {exc}") from None
    if opts.feed not in feeds:
        raise UserError(f"--feed {opts.feed}: with --vehicle {vehicle}, --feed is one of {', '.join(feeds)}")
    check_method(opts.method)
    m = load_mission(opts.mission, opts.scenario)
    if m.scenario not in FOREIGN_SCENARIOS:
        names = ", ".join(FOREIGN_SCENARIOS)
        raise UserError(f"--scenario {m.scenario}: with --vehicle {vehicle}, one of {names} "
                        "(the autopilot's own IMU flies; only the GNSS is ours)")
    if not 0 <= opts.profile < len(m.profiles):
        raise UserError(f"--profile {opts.profile}: mission {m.name!r} has profiles 0..{len(m.profiles) - 1}")
    route = planned_route(m, opts.profile, 0.0)
    sim = sim_config_for(m)
    start_ned = np.array([*m.profiles[opts.profile].start_ne_m, 0.0])
    lat, lon, alt = NedToGeodetic(m.frame)(start_ned)
    closed = opts.feed != "none"
    source: UrbanGnssSource | CanyonGnssSource
    if sim.receiver.enabled:  # the receiver's own Doppler velocity and accuracies
        sigma = None
        source = CanyonGnssSource(sim.receiver, m.world, m.frame, np.random.default_rng(opts.seed),
                                  velocity=cfg.gnss_velocity or closed)
    else:
        # open loop: the EKF gets the Doppler velocity (unless switched off); closed loop: the companion
        # (which fuses no GNSS velocity) reads the raw fixes, so they carry the same velocity for the record
        sigma = cfg.gnss_velocity_sigma_m_s if cfg.gnss_velocity or closed else None
        source = UrbanGnssSource(sim.gnss, m.world, m.frame, cfg.gnss_rate_hz,
                                 np.random.default_rng(opts.seed), float(m.world.clearance_m(*start_ned[:2])),
                                 sigma, np.random.default_rng([opts.seed, VELOCITY_SEED_STREAM]))
    return FlightPlan(m, route, sim, (float(lat), float(lon), float(alt)), closed, sigma, source)


def run_info(plan: FlightPlan, cfg: ForeignFlightConfig, session: ForeignSession, run: SessionRun,
             parameters: dict[str, float]) -> dict[str, Any]:
    """The run section of a flight's summary (the vehicle adds its own keys)."""
    rec, driver = session.rec, session.driver
    wall_s = run.wall_s
    sim_s = (rec.imu_t_us[-1] - rec.imu_t_us[0]) * 1e-6 if rec.imu_t_us else 0.0
    delay, feed_delay = delay_stats(session.command_delay_us), delay_stats(session.feed_delay_us)
    return {
        "ended_by": run.ended_by, "parameters": parameters,
        "gnss_velocity": gnss_velocity_text(plan),
        "phase_times_s": {k: v * 1e-6 for k, v in driver.phase_times_us.items()},
        "sim_s": sim_s, "wall_s": wall_s, "session_cpu_s": run.cpu_s,
        "sim_s_per_wall_s": sim_s / wall_s if wall_s > 0 else math.nan,
        "messages_received": rec.counts, "rejected": rec.rejected, "setpoints_sent": session.setpoints_sent,
        # extra delay (autopilot time) of everything we send, from its scheduler: our fixes reach
        # its EKF this much later than the model's latency says (the companion's fixes do not have it)
        "command_delay_ms": delay,
        # closed loop: the companion's estimates reach the autopilot this late (its process's lag)
        "feed_delay_ms": feed_delay,
        "valid": bool(delay["p95"] <= cfg.max_command_delay_ms
                      and (not plan.closed or feed_delay["p95"] <= cfg.max_command_delay_ms)),
        "statustext": [f"{t * 1e-6:.1f} s {s}" for t, s in rec.statustext[-40:]],
    }


def gnss_velocity_text(plan: FlightPlan) -> str | None:
    """What the raw fixes' velocity is (None: position only)."""
    canyon, sigma = plan.canyon, plan.velocity_sigma_m_s
    if canyon is not None:
        return "the receiver's Doppler solution" if canyon.velocity else None
    return None if sigma is None else f"truth + N(0, {sigma:g} m/s) per axis"


def receiver_info(source: CanyonGnssSource) -> dict[str, Any]:
    """The canyon receiver's run: epochs measured and released, fixes, unsolved epochs, its sky."""
    model = source.model
    return {"epochs": model.epochs, "epochs_released": len(source.raw), "fixes": model.sent,
            "unsolved": model.unsolved, "t0_gps_s": model.t0_gps_s, "rate_hz": model.cfg.rate_hz,
            "systems": list(model.cfg.systems), "ubx": "receiver.ubx", "info": "receiver.json"}


def companion_info(plan: FlightPlan, companion_dir: Path, run: SessionRun,
                   feed: str) -> tuple[dict[str, Any], tuple[np.ndarray, np.ndarray]]:
    """The companion process's run (its summary.json) and what it sent (its tlog), mission frame."""
    summary = read_summary(companion_dir)
    info = {"command": " ".join(run.companion_command[1:]), "exit_code": run.companion_exit_code,
            "node": summary.get("node"),
            "samples": summary.get("samples"), "gnss_delay": summary.get("gnss_delay"),
            "timesync": summary.get("timesync"), "problems": summary.get("problems")}
    live = sent_track(companion_dir / "run.tlog", feed, LocalNedFrame(*plan.home), plan.mission.frame)
    return info, live


@contextlib.contextmanager
def receiver_stream(plan: FlightPlan, out_dir: Path) -> Iterator[ReceiverStream | None]:
    """The canyon receiver's UBX stream for the flight (None without one): a TCP port on 127.0.0.1
    (the closed loop's companion reads it), ``receiver.ubx`` (every frame) and ``receiver.json`` (its
    sky) in ``out_dir``; the source hands it each raw epoch as it is released."""
    canyon = plan.canyon
    if canyon is None:
        yield None
        return
    stream = ReceiverStream(canyon.model, 0, out_dir)
    canyon.raw_sink = stream.send
    try:
        yield stream
    finally:
        canyon.raw_sink = None
        stream.close()


def tight_arguments(stream: ReceiverStream | None) -> tuple[str, ...]:
    """The companion's options for the receiver it owns (the tightly coupled filter on its UBX)."""
    return () if stream is None else ("--coupling", "tight", "--ubx", stream.server.url)


@dataclass(frozen=True)
class SessionRun:
    ended_by: str
    companion_command: list[str]  # [] in open loop
    companion_exit_code: int | None
    wall_s: float
    cpu_s: float


def run_session(session: ForeignSession, sitl_running: Callable[[], bool],
                companion: Callable[[], list[str]] | None, companion_dir: Path) -> SessionRun:
    """Connect, start the companion process (closed loop: ``companion()`` gives its command line,
    asked once the session is connected), fly until the driver is done; the companion is stopped
    (SIGTERM: its summary is written) and the session closed whatever happens."""
    process: CompanionProcess | None = None
    cmd: list[str] = []
    wall0, cpu0 = time.perf_counter(), time.process_time()
    try:
        session.connect(sitl_running)
        if companion is not None:
            cmd = companion()
            process = CompanionProcess(cmd, companion_dir / "companion.log").start()

        def alive() -> bool:
            return sitl_running() and (process is None or process.running())

        ended_by = session.run(alive)
        if process is not None and not process.running() and ended_by == "sitl_exited":
            ended_by = "companion_exited"
    finally:
        exit_code = process.stop() if process is not None else None
        session.close()
    return SessionRun(ended_by, cmd, exit_code, time.perf_counter() - wall0, time.process_time() - cpu0)
