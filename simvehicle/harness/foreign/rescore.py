"""A foreign-autopilot flight scored again from what it recorded (``run.tlog``, ``summary.json``, the
closed loop's ``companion/run.tlog``), without flying it: the flight is planned again from its
summary (mission, profile, seed, feed), its session replayed (``foreign.replay``) and every row
scored as the flight scores it, with the estimator code of now. Each vehicle gives its session
(``px4.rescore``, ``ardupilot.rescore``).

Used by ``beliefnav evaluate --vehicle ardupilot|px4 --resume`` for flights recorded before
campaigns kept every row's error series; the campaign takes the result only if it reproduces the
flight's recorded per-row statistics exactly (``gcs_tools.evaluate.autopilot.same_scores``), so a
flight whose code has changed since is flown again.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from companion.domain.geodesy import LocalNedFrame
from companion.errors import UserError
from simvehicle.harness.backend import FlightResult
from simvehicle.harness.foreign.companion_process import sent_track
from simvehicle.harness.foreign.config import ForeignFlightConfig, ForeignFlightOptions
from simvehicle.harness.foreign.flight import FlightPlan, plan_flight
from simvehicle.harness.foreign.replay import replay
from simvehicle.harness.foreign.scoring import Vehicle, score_flight
from simvehicle.harness.foreign.session import ForeignSession

# (plan, config, the summary's run section) -> (a session never connected, our (system, component)
# in its tlog, the autopilot's)
Ids = tuple[int, int]
SessionFor = Callable[[FlightPlan, Any, dict[str, Any]], tuple[ForeignSession, Ids, Ids]]


def rescore(vehicle: Vehicle, feeds: tuple[str, ...], options: Callable[..., ForeignFlightOptions],
            session_for: SessionFor, out_dir: Path, mission: str, methods: tuple[str, ...],
            config: ForeignFlightConfig, scenario: str | None = None) -> FlightResult:
    """The flight in ``out_dir`` (flown with ``config`` and ``methods``) scored again."""
    try:
        recorded = json.loads((out_dir / "summary.json").read_text())
        run_info: dict[str, Any] = recorded[vehicle.name]
        opts = options(mission, int(recorded["profile"]), str(recorded["method"]), int(recorded["seed"]),
                       out_dir, feed=str(recorded["feed"]), methods=methods, config=config, scenario=scenario)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise UserError(f"{out_dir}: no readable {vehicle.name} flight summary ({exc})") from None
    plan = plan_flight(vehicle.name, opts, config, feeds)
    m = plan.mission
    session, own, target = session_for(plan, config, run_info)
    try:
        replay(session, out_dir / "run.tlog", own, target)
    finally:
        session.tlog.close()
    live = None
    if plan.closed:
        live = sent_track(out_dir / "companion" / "run.tlog", opts.feed, LocalNedFrame(*plan.home), m.frame)
    return score_flight(vehicle, opts, m, plan.route, session.rec, plan.source, session.driver, run_info,
                        plan.sim.vehicle.radius_m, live)
