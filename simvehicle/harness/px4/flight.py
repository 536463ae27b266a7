"""One mission profile flown by PX4 SITL (SIH quadrotor) on our degraded GNSS, end to end.

``fly_px4(options)``: plan the route (A*, minimum jerk), start PX4 SITL with SIH's origin at the
profile's start point (``PX4_HOME_LAT/LON/ALT``) and no GNSS of its own, run the session (GNSS
source as HIL_GPS + OFFBOARD driver) until the goal is reached or time runs out, then score EKF2
and every companion method on the recorded samples (``foreign.scoring``). Closed loop (``--feed
odometry``): ``beliefnav companion`` runs as its own process on PX4's onboard link, reads the raw
fixes back as GPS_RAW_INT and feeds ODOMETRY, which EKF2 fuses as external vision instead of
any GNSS; what it sent is scored too (row ``companion-live``).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from pathlib import Path

from companion.errors import UserError
from simvehicle.harness.backend import FlightResult
from simvehicle.harness.foreign import flight as foreign
from simvehicle.harness.foreign.companion_process import companion_command
from simvehicle.harness.foreign.config import ForeignFlightOptions
from simvehicle.harness.foreign.scoring import Vehicle, score_flight
from simvehicle.harness.px4.config import FEEDS, Px4FlightConfig, px4_parameters
from simvehicle.harness.px4.driver import OffboardDriver
from simvehicle.harness.px4.session import Px4Session
from simvehicle.harness.px4.sitl import MAX_INSTANCE, Px4Config, Px4Sitl

PX4 = Vehicle("px4", "px4-ekf2")
INSTANCE_RANGE = (0, MAX_INSTANCE + 1)  # -i 0..9 (above 9 PX4's onboard ports collide)


@dataclass(frozen=True)
class Px4FlightOptions(ForeignFlightOptions):
    config: Px4FlightConfig = field(default_factory=Px4FlightConfig)
    instance_range: tuple[int, int] = INSTANCE_RANGE
    px4_dir: Path | None = None  # bin/px4 and etc/ (None: $BELIEFNAV_PX4_DIR, else the shared build)


def fly_px4(opts: Px4FlightOptions) -> FlightResult:
    cfg = opts.config
    plan = foreign.plan_flight(PX4.name, opts, cfg, FEEDS)
    m = plan.mission
    driver = OffboardDriver(cfg, plan.route, m.altitude_m, warmup_s=cfg.offboard_warmup_s)
    opts.out_dir.mkdir(parents=True, exist_ok=True)
    if plan.canyon is not None and plan.closed:
        raise UserError("--scenario canyon with --vehicle px4: open loop only (--feed none); PX4's "
                        "SYSTEM_TIME is the host's clock, not the receiver's GPS time, so a companion could "
                        "not put the raw epochs on its boot clock")
    params = px4_parameters(cfg, opts.feed, canyon=plan.canyon is not None)
    px4_dir = opts.out_dir / "px4"
    sitl_cfg = Px4Config(work_dir=px4_dir, px4_dir=opts.px4_dir, speed_factor=cfg.speed_factor,
                         instance_range=opts.instance_range, home=plan.home, params=params, logging=cfg.ulog)
    companion_dir = opts.out_dir / "companion"
    with foreign.receiver_stream(plan, opts.out_dir), Px4Sitl(sitl_cfg) as sitl:
        session = Px4Session(sitl.gcs_url, sitl.system_id, cfg, m.frame, plan.source, driver,
                             opts.out_dir / "run.tlog")

        def companion() -> list[str]:  # PX4's onboard link, as a user starts it beside PX4
            return companion_command(sitl.url, companion_dir, opts.feed, opts.method, plan.home,
                                     "--target-system", str(sitl.system_id), mission=opts.mission)

        run = foreign.run_session(session, sitl.running, companion if plan.closed else None, companion_dir)
        instance = sitl.instance
        sitl.stop()  # the logger closes its ULog
        ulogs = [str(p.relative_to(opts.out_dir)) for p in sitl.ulogs()]
    shutil.rmtree(px4_dir / "bin", ignore_errors=True)  # the copied firmware (4 MB), not a result
    info = {"instance": instance, "speed_factor": cfg.speed_factor, "feed": opts.feed,
            **foreign.run_info(plan, cfg, session, run, params), "hil_gps_sent": session.gps_sent,
            "local_frame": {"ekf2_origin": session.origin_lla, "ground_z_m": session.ground_z_m},
            "ulogs": ulogs}
    if plan.canyon is not None:
        info["receiver"] = foreign.receiver_info(plan.canyon)
    live = None
    if plan.closed:
        info["companion"], live = foreign.companion_info(plan, companion_dir, run, opts.feed)
    return score_flight(PX4, opts, m, plan.route, session.rec, plan.source, driver, info,
                        plan.sim.vehicle.radius_m, live)
