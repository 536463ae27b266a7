"""``ArduPilotBackend`` (``backend("ardupilot")``): ArduCopter SITL flying a mission profile on our
degraded GNSS (``flight.fly_ardupilot``), EKF3 and the companion's methods scored on its samples."""

from __future__ import annotations

from typing import Any

from companion.errors import UserError
from simvehicle.harness.ardupilot.flight import ArduPilotFlightOptions, fly_ardupilot
from simvehicle.harness.backend import FlightRequest, FlightResult, mission_name


class ArduPilotBackend:
    """``options``: ``ArduPilotFlightOptions``' other fields (feed, config, methods, instance_range,
    estimator)."""

    name = "ardupilot"

    def __init__(self, **options: Any) -> None:
        self.options = options

    def fly(self, request: FlightRequest) -> FlightResult:
        if request.out_dir is None:
            raise UserError("the ardupilot backend runs processes: it needs an output directory")
        if request.scenario is not None or request.max_duration_s is not None:
            raise UserError("--scenario and --max-duration-s apply to our simulated vehicle only")
        return fly_ardupilot(ArduPilotFlightOptions(
            mission=mission_name(request, self.name), profile=request.profile, method=request.method,
            seed=request.seed, out_dir=request.out_dir, **self.options))
