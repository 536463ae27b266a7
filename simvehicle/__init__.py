"""Simulated quadrotor: urban world truth, dynamics, autopilot, IMU and GNSS degradation.

Imports from ``companion`` only the shared contracts: ``companion.mission`` (mission/map
schema) and ``companion.domain``/``companion.mavlink``/``companion.telemetry`` (types and
codecs). Never the estimator.
"""

from simvehicle.config import SimConfig
from simvehicle.vehicle import SimVehicle, StepOutput

__all__ = ["SimConfig", "SimVehicle", "StepOutput"]
