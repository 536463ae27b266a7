"""``SitlBackend`` (``backend("sim")``): our simulated vehicle, estimator and bridge as three
MAVLink/UDP processes (``launcher``), the run turned into a ``FlightResult`` (``result``) with the
one-line reason it failed (``outcome``)."""

from __future__ import annotations

from typing import Any

from companion.errors import UserError
from companion.mission import load_mission
from simvehicle.harness.backend import FlightRequest, FlightResult, mission_name
from simvehicle.harness.sitl.launcher import Progress, SitlOptions, flight_plan, launch
from simvehicle.harness.sitl.outcome import failure_reason
from simvehicle.harness.sitl.result import flight_result


class SitlBackend:
    """``options``: ``SitlOptions``' other fields (realtime, signing, ports, telemetry_args, ...);
    ``progress(t_s, goal_distance_m)`` is called as the vehicle reports."""

    name = "sim"

    def __init__(self, progress: Progress | None = None, **options: Any) -> None:
        self.progress = progress
        self.options = options

    def fly(self, request: FlightRequest) -> FlightResult:
        if request.out_dir is None:
            raise UserError("the sim backend runs processes: it needs an output directory")
        opts = SitlOptions(mission=mission_name(request, self.name), profile=request.profile,
                           method=request.method, seed=request.seed, out_dir=request.out_dir,
                           max_duration_s=request.max_duration_s, scenario=request.scenario, **self.options)
        route, _ = flight_plan(opts)
        run = launch(opts, self.progress)
        result = flight_result(opts, run, route, load_mission(opts.mission).name)
        return FlightResult(result.summary, result.series, route, failure_reason(run, result.summary))
