"""What every flight beside a foreign autopilot is run with (units in the names); each vehicle's
configuration (``ArduPilotConfig``, ``Px4FlightConfig``) adds its own fields and checks."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from companion.estimator import METHODS, EstimatorConfig
from companion.tight import WEIGHTINGS
from simvehicle.config import _positive


@dataclass(frozen=True)
class ForeignFlightConfig:
    stream_rate_hz: float = 50.0  # HIGHRES_IMU, ATTITUDE_QUATERNION and the truth message, requested rate
    estimate_rate_hz: float = 10.0  # the autopilot's own estimate (GLOBAL_POSITION_INT / LOCAL_POSITION_NED)
    gnss_rate_hz: float = 10.0  # our degradation model's fix rate (a receiver's 5-20 Hz)
    gps_delay_ms: int = 100  # the receiver delay the autopilot's EKF assumes (our open-sky mean latency)
    # Doppler velocity in the raw fixes (our model makes positions only): the autopilot's TRUE velocity
    # at the fix's validity time plus white noise of this std per axis, sent with the fix (same
    # latency) and fused by its EKF. False: position only.
    gnss_velocity: bool = True
    gnss_velocity_sigma_m_s: float = 0.1  # a u-blox M8/M9's typical 0.05-0.1 m/s speed accuracy
    setpoint_rate_hz: float = 20.0  # SET_POSITION_TARGET_LOCAL_NED rate
    takeoff_tolerance_m: float = 1.0  # take-off done once within this of the mission altitude
    hover_before_route_s: float = 3.0  # settle after take-off before the route's clock starts
    goal_radius_m: float = 2.0  # as fly: true position within this of the goal ...
    goal_speed_m_s: float = 1.0  # ... and slower than this, after the reference arrived
    timeout_margin_s: float = 30.0  # route phase limit: duration + max(margin, 50 % of the duration)
    setup_timeout_s: float = 180.0  # simulated seconds allowed for boot, EKF ready, arming, take-off
    connect_timeout_s: float = 20.0  # wall seconds to reach the SITL and get a HEARTBEAT
    wall_timeout_s: float = 600.0  # whole flight, wall clock
    # A flight whose commands (fixes, setpoints) reached the autopilot later than this (p95, in its
    # time) measured the machine's scheduler, not the estimators: it is flagged invalid (neither SITL
    # waits for us; a loaded machine needs a lower speed-up).
    max_command_delay_ms: float = 100.0

    def validate(self) -> None:
        _positive(self, "stream_rate_hz", "estimate_rate_hz", "gnss_rate_hz", "setpoint_rate_hz",
                  "goal_radius_m", "setup_timeout_s", "connect_timeout_s", "wall_timeout_s")
        if not 5.0 <= self.gnss_rate_hz <= 20.0:
            raise ValueError(f"gnss_rate_hz: a receiver's 5-20 Hz, got {self.gnss_rate_hz!r}")
        if not self.gnss_velocity_sigma_m_s >= 0:
            raise ValueError(f"gnss_velocity_sigma_m_s: must be >= 0, got {self.gnss_velocity_sigma_m_s!r}")


@dataclass(frozen=True)
class ForeignFlightOptions:
    """One flight; each vehicle's options add its ``config`` and instance range."""

    mission: str  # a name or path (a process backend passes it on)
    profile: int  # the mission's profile index
    method: str  # the companion's method (the closed loop's process, the flight's own row)
    seed: int  # our GNSS model's draws
    out_dir: Path  # run.tlog, the SITL's work directory, the companion's
    feed: str = "none"
    # sensor scenario (None: the mission file's): paper = our eq. 22-27 fixes; canyon = the calibrated
    # raw receiver in the 3-D city (its fixes to the autopilot, its raw epochs recorded and, in closed
    # loop, served as UBX to the tightly coupled companion). The autopilot's own IMU flies either way.
    scenario: str | None = None
    methods: tuple[str, ...] = METHODS  # every companion method evaluated on the same samples
    # scenario canyon: the tightly coupled weightings run on the receiver's raw epochs (rows tight-<w>)
    tight_methods: tuple[str, ...] = WEIGHTINGS
    # The filter's defaults are those of real sensors (the quad106 log). A mission's ``estimator:``
    # section describes OUR simulated IMU (0.006 m/s² noise, true attitude), not the autopilot's,
    # so it is not used here; nothing was tuned on SITL flights.
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
