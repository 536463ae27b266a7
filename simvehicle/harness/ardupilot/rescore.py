"""An ArduPilot flight scored again from its tlogs, without ArduCopter (``foreign.rescore``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from simvehicle.harness.ardupilot.config import FEEDS, GPS1_ID, GPS2_ID, ArduPilotConfig
from simvehicle.harness.ardupilot.driver import FlightDriver
from simvehicle.harness.ardupilot.flight import ARDUPILOT, ArduPilotFlightOptions
from simvehicle.harness.ardupilot.session import GCS_COMPONENT_ID, GCS_SYSTEM_ID, ArduPilotSession
from simvehicle.harness.backend import FlightResult
from simvehicle.harness.foreign.flight import FlightPlan
from simvehicle.harness.foreign.rescore import rescore
from simvehicle.harness.foreign.session import ForeignSession

AUTOPILOT = (1, 1)  # ArduCopter SITL's system and component (SYSID_THISMAV 1)


def _session(plan: FlightPlan, cfg: ArduPilotConfig,
             run_info: dict[str, Any]) -> tuple[ForeignSession, tuple[int, int], tuple[int, int]]:
    driver = FlightDriver(cfg, plan.route, plan.mission.altitude_m)
    session = ArduPilotSession(0, cfg, plan.mission.frame, plan.source, driver, Path(os.devnull),
                               GPS2_ID if plan.closed else GPS1_ID)
    return session, (GCS_SYSTEM_ID, GCS_COMPONENT_ID), AUTOPILOT


def rescore_ardupilot(out_dir: Path, mission: str, methods: tuple[str, ...], config: ArduPilotConfig,
                      scenario: str | None = None) -> FlightResult:
    """The flight in ``out_dir`` (flown with ``config``, ``methods`` and ``scenario``) scored again."""
    return rescore(ARDUPILOT, FEEDS, ArduPilotFlightOptions, _session, out_dir, mission, methods, config,
                   scenario)
