"""One mission profile flown by ArduCopter SITL on our degraded GNSS, end to end.

``fly_ardupilot(options)``: plan the route (A*, minimum jerk), start ArduCopter SITL at the
profile's start point (``--home``; its EKF origin is read back from GPS_GLOBAL_ORIGIN), run the
session (GNSS source + flight driver) until the goal is reached or time runs out, then evaluate
EKF3 and every companion method on the recorded samples. Closed loop (``--feed gps-input|vision``):
the companion runs as its own process beside the SITL (``foreign.companion_process``), on SERIAL1, and
what it sent ArduPilot is scored too (row ``companion-live``). Returns ``fly``'s ``FlightResult`` (the
same summary keys and series, plus the EKF3 and per-method figures) for ``write_outputs``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from simvehicle.harness.ardupilot.config import FEEDS, GPS1_ID, GPS2_ID, ArduPilotConfig, ardupilot_parameters
from simvehicle.harness.ardupilot.driver import FlightDriver
from simvehicle.harness.ardupilot.session import ArduPilotSession
from simvehicle.harness.ardupilot.sitl import ArduPilotSitl, SitlConfig
from simvehicle.harness.backend import FlightResult
from simvehicle.harness.foreign.companion_process import companion_command
from simvehicle.harness.foreign.config import ForeignFlightOptions
from simvehicle.harness.foreign.flight import (
    companion_info,
    plan_flight,
    receiver_info,
    receiver_stream,
    run_info,
    run_session,
    tight_arguments,
)
from simvehicle.harness.foreign.scoring import Vehicle, score_flight

ARDUPILOT = Vehicle("ardupilot", "ardupilot-ekf3")
INSTANCE_RANGE = (20, 40)  # -I 20..39: this tool's instances (ports 5960..6153)


@dataclass(frozen=True)
class ArduPilotFlightOptions(ForeignFlightOptions):
    config: ArduPilotConfig = field(default_factory=ArduPilotConfig)
    instance_range: tuple[int, int] = INSTANCE_RANGE


def fly_ardupilot(opts: ArduPilotFlightOptions) -> FlightResult:
    cfg = opts.config
    plan = plan_flight(ARDUPILOT.name, opts, cfg, FEEDS)
    m = plan.mission
    driver = FlightDriver(cfg, plan.route, m.altitude_m)
    opts.out_dir.mkdir(parents=True, exist_ok=True)
    canyon = plan.canyon
    params = ardupilot_parameters(cfg, opts.feed, canyon=canyon is not None,
                                  receiver_latency_ms=None if canyon is None else
                                  round(canyon.model.cfg.latency_s * 1000))
    sitl_cfg = SitlConfig(work_dir=opts.out_dir / "ardupilot", home=(*plan.home, 0.0), speedup=cfg.speedup,
                          params=params, instance_range=opts.instance_range)
    companion_dir = opts.out_dir / "companion"
    with receiver_stream(plan, opts.out_dir) as stream, ArduPilotSitl(sitl_cfg) as sitl:
        session = ArduPilotSession(sitl.ports[0], cfg, m.frame, plan.source, driver,
                                   opts.out_dir / "run.tlog", GPS2_ID if plan.closed else GPS1_ID)

        def companion() -> list[str]:  # SERIAL1 listens once SERIAL0 has its client
            return companion_command(sitl.wait_serial(1), companion_dir, opts.feed, opts.method, plan.home,
                                     "--gnss-instance", "2", "--target-system", "1", *tight_arguments(stream),
                                     mission=opts.mission)

        run = run_session(session, sitl.running, companion if plan.closed else None, companion_dir)
        instance = sitl.instance
    info = {"instance": instance, "speedup": cfg.speedup, "feed": opts.feed,
            **run_info(plan, cfg, session, run, params), "gps_input_sent": session.gps_sent}
    live = None
    if plan.canyon is not None:
        info["receiver"] = receiver_info(plan.canyon)
    if plan.closed:
        info["companion"], live = companion_info(plan, companion_dir, run, opts.feed)
    return score_flight(ARDUPILOT, opts, m, plan.route, session.rec, plan.source, driver, info,
                        plan.sim.vehicle.radius_m, live)
