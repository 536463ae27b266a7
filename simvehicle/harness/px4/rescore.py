"""A PX4 flight scored again from its tlogs, without PX4 (``foreign.rescore``): its session is
replayed as the vehicle's system ``instance + 1`` that it flew as."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from simvehicle.harness.backend import FlightResult
from simvehicle.harness.foreign.flight import FlightPlan
from simvehicle.harness.foreign.rescore import rescore
from simvehicle.harness.foreign.session import ForeignSession
from simvehicle.harness.px4.config import FEEDS, Px4FlightConfig
from simvehicle.harness.px4.driver import OffboardDriver
from simvehicle.harness.px4.flight import PX4, Px4FlightOptions
from simvehicle.harness.px4.session import FLIGHT_TOOL_COMPONENT_ID, Px4Session

PX4_COMPONENT_ID = 1  # the autopilot's component (connect's target)


def _session(plan: FlightPlan, cfg: Px4FlightConfig,
             run_info: dict[str, Any]) -> tuple[ForeignSession, tuple[int, int], tuple[int, int]]:
    system_id = int(run_info["instance"]) + 1
    m = plan.mission
    driver = OffboardDriver(cfg, plan.route, m.altitude_m, warmup_s=cfg.offboard_warmup_s)
    session = Px4Session("udpout:127.0.0.1:9", system_id, cfg, m.frame, plan.source, driver, Path(os.devnull))
    return session, (system_id, FLIGHT_TOOL_COMPONENT_ID), (system_id, PX4_COMPONENT_ID)


def rescore_px4(out_dir: Path, mission: str, methods: tuple[str, ...], config: Px4FlightConfig,
                scenario: str | None = None) -> FlightResult:
    """The flight in ``out_dir`` (flown with ``config``, ``methods`` and ``scenario``) scored again."""
    return rescore(PX4, FEEDS, Px4FlightOptions, _session, out_dir, mission, methods, config, scenario)
