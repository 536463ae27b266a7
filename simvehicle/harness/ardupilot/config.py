"""Parameters of a flight beside ArduCopter SITL: the ONE place their values live."""

from __future__ import annotations

from dataclasses import dataclass

# ArduPilot's GPS_INPUT ignore_flags: velocity (horizontal, vertical) and speed accuracy are not sent.
GPS_INPUT_IGNORE_VELOCITY = 8 | 16 | 32
GPS_WEEK = 2400  # any plausible GPS week: ArduPilot uses week/ms only as a clock (jitter correction)
# GPS_INPUT gps_id = ArduPilot's receiver instance (GPS1 = 0, GPS2 = 1). Closed loop: the raw
# degraded fixes go to GPS2, which EKF3 does not use, and the companion reads them as GPS2_RAW.
GPS1_ID, GPS2_ID = 0, 1
FEEDS = ("none", "gps-input", "vision")  # what ArduPilot flies on: EKF3 on the raw fixes, or the companion


@dataclass(frozen=True)
class ArduPilotConfig:
    """How ArduCopter SITL is run, fed and flown (units in the names)."""

    speedup: float = 10.0  # SITL --speedup (measured stable at 10 on a loaded 2-core machine)
    stream_rate_hz: float = 50.0  # HIGHRES_IMU, ATTITUDE_QUATERNION, SIM_STATE (truth) requested rate
    estimate_rate_hz: float = 10.0  # GLOBAL_POSITION_INT, LOCAL_POSITION_NED (EKF3's estimate)
    gnss_rate_hz: float = 10.0  # GPS_INPUT rate from our degradation model (ArduPilot takes 5-20 Hz)
    gps_delay_ms: int = 100  # GPS1_DELAY_MS: the receiver delay EKF3 assumes (our open-sky mean latency)
    # Doppler velocity in the raw GPS_INPUT (our model makes positions only): ArduPilot's TRUE velocity
    # at the fix's validity time plus white noise of this std per axis, sent with the fix (same
    # latency) and fused by EKF3 (EK3_SRC1_VELXY/VELZ 3, its defaults). False: position only.
    gnss_velocity: bool = True
    gnss_velocity_sigma_m_s: float = 0.1  # a u-blox M8/M9's typical 0.05-0.1 m/s speed accuracy
    setpoint_rate_hz: float = 20.0  # SET_POSITION_TARGET_LOCAL_NED rate
    takeoff_tolerance_m: float = 1.0  # take-off done once within this of the mission altitude
    hover_before_route_s: float = 3.0  # settle after take-off before the route's clock starts
    goal_radius_m: float = 2.0  # as fly: true position within this of the goal ...
    goal_speed_m_s: float = 1.0  # ... and slower than this, after the reference arrived
    timeout_margin_s: float = 30.0  # route phase limit: duration + max(margin, 50 % of the duration)
    setup_timeout_s: float = 180.0  # simulated seconds allowed for boot, EKF3 GPS use, arming, take-off
    connect_timeout_s: float = 20.0  # wall seconds to reach the SITL's TCP port and get a HEARTBEAT
    wall_timeout_s: float = 600.0  # whole flight, wall clock
    # A flight whose commands (GPS_INPUT, setpoints) reached ArduPilot later than this (p95, in
    # ArduPilot time) measured the machine's scheduler, not the estimators: it is flagged invalid
    # (SITL does not wait for us; a loaded machine needs a lower --speedup).
    max_command_delay_ms: float = 100.0

    def validate(self) -> None:
        for name in ("speedup", "stream_rate_hz", "estimate_rate_hz", "gnss_rate_hz", "setpoint_rate_hz",
                     "goal_radius_m", "setup_timeout_s", "connect_timeout_s", "wall_timeout_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)!r}")
        if not 5.0 <= self.gnss_rate_hz <= 20.0:
            raise ValueError(f"gnss_rate_hz: GPS_INPUT is taken at 5-20 Hz, got {self.gnss_rate_hz!r}")
        if not 0 < self.gps_delay_ms <= 250:
            raise ValueError(f"gps_delay_ms: GPS1_DELAY_MS must be 1..250 ms, got {self.gps_delay_ms}")
        if not self.gnss_velocity_sigma_m_s >= 0:
            raise ValueError(f"gnss_velocity_sigma_m_s: must be >= 0, got {self.gnss_velocity_sigma_m_s!r}")


def ardupilot_parameters(cfg: ArduPilotConfig, feed: str = "none") -> dict[str, float]:
    """Parameters set at boot (a defaults file beside copter.parm, so those needing a reboot apply).

    Open loop (``none``): GPS1_TYPE 14 makes our raw GPS_INPUT EKF3's ONLY GNSS. With
    ``gnss_velocity`` it fuses position and the Doppler velocity (EK3_SRC1_VELXY/VELZ 3, the
    defaults); without, position only (VELXY/VELZ 0: a GPS_INPUT without velocity would otherwise
    be read as zero velocity). Height stays on the barometer (EK3_SRC1_POSZ 1, ArduPilot's
    default), which the companion does not have: compare horizontal errors for that.

    Closed loop: the raw fixes go to a SECOND MAVLink receiver (GPS2_TYPE 14, gps_id 1) that EKF3
    does not use (GPS_AUTO_SWITCH 0, GPS_PRIMARY 0: EKF3 takes the primary, GPS1); the companion
    reads it back as GPS2_RAW. ``gps-input``: GPS1 = the companion's cleaned fix, current when sent
    (GPS1_DELAY_MS 1) and with the filter's velocity, so EKF3 keeps its default sources.
    ``vision``: no GPS1 (GPS1_TYPE 0); EKF3 fuses the companion's VISION_POSITION_ESTIMATE as
    ExternalNav (VISO_TYPE 1, EK3_SRC1_POSXY 6, VELXY 0, POSZ 1 barometer, YAW 1 compass) and its
    origin is set by the companion (SET_GPS_GLOBAL_ORIGIN).
    """
    second_receiver = {"GPS2_TYPE": 14, "GPS2_DELAY_MS": cfg.gps_delay_ms, "GPS_AUTO_SWITCH": 0,
                       "GPS_PRIMARY": 0}
    if feed == "gps-input":
        return {"GPS1_TYPE": 14, "GPS1_DELAY_MS": 1, **second_receiver}
    if feed == "vision":
        # ArduPilot refuses to arm with a primary of TYPE 0 ("GPS 1: primary but TYPE 0"): GPS2 is the
        # primary, which EKF3 only reads as a position/velocity source if told to (it is not here)
        return {"GPS1_TYPE": 0, **second_receiver, "GPS_PRIMARY": 1, "VISO_TYPE": 1, "EK3_SRC1_POSXY": 6,
                "EK3_SRC1_VELXY": 0, "EK3_SRC1_POSZ": 1, "EK3_SRC1_VELZ": 0, "EK3_SRC1_YAW": 1}
    if cfg.gnss_velocity:
        return {"GPS1_TYPE": 14, "GPS1_DELAY_MS": cfg.gps_delay_ms, "EK3_SRC1_VELXY": 3, "EK3_SRC1_VELZ": 3}
    return {"GPS1_TYPE": 14, "GPS1_DELAY_MS": cfg.gps_delay_ms, "EK3_SRC1_VELXY": 0, "EK3_SRC1_VELZ": 0}
