"""``ArduPilotBackend`` (``backend("ardupilot")``): ArduCopter SITL flying a mission profile on our
degraded GNSS (``flight.fly_ardupilot``), EKF3 and the companion's methods scored on its samples."""

from __future__ import annotations

from typing import Any

from simvehicle.harness.ardupilot.flight import ArduPilotFlightOptions, fly_ardupilot
from simvehicle.harness.backend import FlightResult
from simvehicle.harness.foreign.backend import ForeignBackend


class ArduPilotBackend(ForeignBackend):
    """``options``: ``ArduPilotFlightOptions``' other fields (feed, config, methods, instance_range,
    estimator)."""

    name = "ardupilot"

    def fly_options(self, **fields: Any) -> FlightResult:
        return fly_ardupilot(ArduPilotFlightOptions(**fields))
