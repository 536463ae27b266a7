"""``Px4Backend`` (``backend("px4")``): PX4 SITL (SIH quadrotor) flying a mission profile on our
degraded GNSS (``flight.fly_px4``), EKF2 and the companion's methods scored on its samples."""

from __future__ import annotations

from typing import Any

from simvehicle.harness.backend import FlightResult
from simvehicle.harness.foreign.backend import ForeignBackend
from simvehicle.harness.px4.flight import Px4FlightOptions, fly_px4


class Px4Backend(ForeignBackend):
    """``options``: ``Px4FlightOptions``' other fields (feed, config, methods, instance_range,
    estimator, px4_dir)."""

    name = "px4"

    def fly_options(self, **fields: Any) -> FlightResult:
        return fly_px4(Px4FlightOptions(**fields))
