"""``beliefnav fly``: one mission flown in-process (vehicle, planner, autopilot, estimator)."""

from gcs_tools.fly.core import FlightResult, FlyConfig, fly

__all__ = ["FlightResult", "FlyConfig", "fly"]
