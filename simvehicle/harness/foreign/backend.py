"""What a foreign-autopilot backend does with a ``FlightRequest`` before its vehicle's flight starts."""

from __future__ import annotations

from typing import Any, ClassVar

from companion.errors import UserError
from simvehicle.harness.backend import FlightRequest, FlightResult, mission_name


class ForeignBackend:
    """A SITL backend: ``options`` are the vehicle's flight options other than the request's
    (feed, config, methods, instance_range, estimator, ...); ``fly_options`` flies them."""

    name: ClassVar[str]

    def __init__(self, **options: Any) -> None:
        self.options = options

    def fly(self, request: FlightRequest) -> FlightResult:
        if request.out_dir is None:
            raise UserError(f"the {self.name} backend runs processes: it needs an output directory")
        if request.max_duration_s is not None:
            raise UserError("--max-duration-s applies to our simulated vehicle only")
        return self.fly_options(mission=mission_name(request, self.name), profile=request.profile,
                                method=request.method, seed=request.seed, out_dir=request.out_dir,
                                scenario=request.scenario, **self.options)

    def fly_options(self, **fields: Any) -> FlightResult:  # pragma: no cover - each vehicle's
        raise NotImplementedError
