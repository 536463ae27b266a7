"""A PX4 flight scored again from what it recorded (``run.tlog``, ``summary.json``, the closed
loop's ``companion/run.tlog``), without flying it: the session is replayed
(``foreign.replay``) and every row scored as ``fly_px4`` scores it, with the estimator code of now.

Used by ``beliefnav evaluate --vehicle px4 --resume`` for flights recorded before campaigns kept
every row's error series; the campaign takes the result only if it reproduces the flight's
recorded per-row statistics exactly (``gcs_tools.evaluate.autopilot.same_scores``), so a flight
whose code has changed since is flown again.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from companion.domain.geodesy import LocalNedFrame
from companion.errors import UserError
from simvehicle.harness.backend import FlightResult
from simvehicle.harness.foreign.companion_process import sent_track
from simvehicle.harness.foreign.flight import plan_flight
from simvehicle.harness.foreign.replay import replay
from simvehicle.harness.foreign.scoring import score_flight
from simvehicle.harness.px4.config import FEEDS, Px4FlightConfig
from simvehicle.harness.px4.driver import OffboardDriver
from simvehicle.harness.px4.flight import PX4, Px4FlightOptions
from simvehicle.harness.px4.session import FLIGHT_TOOL_COMPONENT_ID, Px4Session

PX4_COMPONENT_ID = 1  # the autopilot's component (connect's target)


def rescore_px4(out_dir: Path, mission: str, methods: tuple[str, ...],
                config: Px4FlightConfig) -> FlightResult:
    """The flight in ``out_dir`` (flown with ``config`` and ``methods``) scored again; its profile,
    seed, feed, method and run section are read from its ``summary.json``."""
    try:
        recorded = json.loads((out_dir / "summary.json").read_text())
        run_info: dict[str, Any] = recorded[PX4.name]
        system_id = int(run_info["instance"]) + 1
        opts = Px4FlightOptions(mission, int(recorded["profile"]), str(recorded["method"]),
                                int(recorded["seed"]), out_dir, str(recorded["feed"]), methods, config=config)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise UserError(f"{out_dir}: no readable PX4 flight summary ({exc})") from None
    plan = plan_flight(PX4.name, opts, config, FEEDS)
    m = plan.mission
    driver = OffboardDriver(config, plan.route, m.altitude_m, warmup_s=config.offboard_warmup_s)
    session = Px4Session("udpout:127.0.0.1:9", system_id, config, m.frame, plan.source, driver,
                         Path(os.devnull))  # never connected: replay() feeds it
    try:
        replay(session, out_dir / "run.tlog", (system_id, FLIGHT_TOOL_COMPONENT_ID),
               (system_id, PX4_COMPONENT_ID))
    finally:
        session.tlog.close()
    live = None
    if plan.closed:
        live = sent_track(out_dir / "companion" / "run.tlog", opts.feed, LocalNedFrame(*plan.home), m.frame)
    return score_flight(PX4, opts, m, plan.route, session.rec, plan.source, driver, run_info,
                        plan.sim.vehicle.radius_m, live)
