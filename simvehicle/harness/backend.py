"""One interface for every vehicle a campaign, a benchmark or the CLI flies (rotorpy's ``Environment``
takes an injected vehicle the same way).

    from simvehicle.harness.backend import FlightRequest, backend
    result = backend("inprocess").fly(FlightRequest("test", profile=0, method="second-order", seed=0))
    result = backend("sim", realtime=False).fly(FlightRequest("test", 0, out_dir=Path("runs/x")))
    result = backend("ardupilot", feed="none").fly(FlightRequest("test", 0, out_dir=Path("runs/ap")))
    result = backend("px4", feed="odometry").fly(FlightRequest("test", 0, out_dir=Path("runs/px4")))

A backend is built by name from ``BACKENDS`` with its own options (keywords of its constructor) and
flies one ``FlightRequest`` at a time, returning a ``FlightResult``: the in-process flight's summary
keys and 20 Hz series (docs/ARCHITECTURE.md), plus what the backend adds (``sitl``, ``ardupilot``
sections). Writing files and figures is the caller's (``gcs_tools``). A new vehicle is one module
with a class following ``VehicleBackend`` and one line in ``BACKENDS`` (a SITL autopilot flown on
our GNSS subclasses ``foreign.backend.ForeignBackend``, as ArduPilot and PX4 do); the CLI's
``beliefnav sitl --vehicle NAME`` lists ``SITL_VEHICLES``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np

from companion.errors import not_one_of
from companion.estimator.methods import DEFAULT_METHOD

if TYPE_CHECKING:
    from companion.mission import Mission
    from companion.planning import Route


@dataclass(frozen=True)
class FlightRequest:
    """One flight: which mission profile, estimator method and seed, and where a backend that runs
    processes keeps what they write (its logs, run.tlog)."""

    mission: str | Mission  # a name or path (every backend), or a loaded Mission (in-process only)
    profile: int = 0
    method: str = DEFAULT_METHOD
    seed: int = 0
    out_dir: Path | None = None  # required by process backends (sim, ardupilot, px4)
    max_duration_s: float | None = None  # simulated time limit (None: the backend's default)
    scenario: str | None = None  # sensor scenario (None: the mission file's)


@dataclass(frozen=True)
class FlightResult:
    summary: dict[str, Any]
    series: dict[str, np.ndarray]  # 20 Hz, see docs/ARCHITECTURE.md
    route: Route
    failure: str = ""  # a process backend's one-line reason the flight failed ("" = none recorded)
    # every GNSS fix received, when the backend knows (see simvehicle.harness.fly._fixes): t_s, t_validity_s,
    # p_ned_m (K, 3), h_acc_m, rejected (1: the innovation gate refused it; NaN: not known)
    fixes: dict[str, np.ndarray] = field(default_factory=dict)


class VehicleBackend(Protocol):
    """A way to fly a mission profile; options are given to the constructor."""

    name: ClassVar[str]

    def fly(self, request: FlightRequest) -> FlightResult: ...


# name -> "module:class", imported when asked for (ArduPilot's harness needs pymavlink, ...)
BACKENDS: dict[str, str] = {
    "inprocess": "simvehicle.harness.fly:InProcessBackend",  # our simulator, one process, no network
    "sim": "simvehicle.harness.sitl.backend:SitlBackend",  # our simulator as three MAVLink/UDP processes
    "ardupilot": "simvehicle.harness.ardupilot.backend:ArduPilotBackend",  # ArduCopter SITL on our GNSS
    "px4": "simvehicle.harness.px4.backend:Px4Backend",  # PX4 SITL (SIH quadrotor) on our GNSS
}
SITL_VEHICLES: tuple[str, ...] = tuple(name for name in BACKENDS if name != "inprocess")  # sitl --vehicle


def backend_class(name: str) -> type[VehicleBackend]:
    """The class registered as ``name`` (a one-line error naming the backends otherwise)."""
    if name not in BACKENDS:
        raise not_one_of("vehicle backend", name, tuple(BACKENDS))
    module, _, attr = BACKENDS[name].partition(":")
    cls: type[VehicleBackend] = getattr(importlib.import_module(module), attr)
    return cls


def backend(name: str, **options: Any) -> VehicleBackend:
    """The backend ``name`` built with its ``options``."""
    return backend_class(name)(**options)


def mission_name(request: FlightRequest, backend_name: str) -> str:
    """The request's mission as a name or path (what a backend that starts processes can pass on)."""
    if not isinstance(request.mission, str):
        raise TypeError(f"the {backend_name} backend flies a mission file: give its name or path")
    return request.mission
