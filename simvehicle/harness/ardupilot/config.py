"""Parameters of a flight beside ArduCopter SITL: the ONE place their values live."""

from __future__ import annotations

from dataclasses import dataclass

from simvehicle.harness.foreign.config import ForeignFlightConfig

# ArduPilot's GPS_INPUT ignore_flags: velocity (horizontal, vertical) and speed accuracy are not sent.
GPS_INPUT_IGNORE_VELOCITY = 8 | 16 | 32
GPS_WEEK = 2400  # any plausible GPS week: ArduPilot uses week/ms only as a clock (jitter correction)
# GPS_INPUT gps_id = ArduPilot's receiver instance (GPS1 = 0, GPS2 = 1). Closed loop: the raw
# degraded fixes go to GPS2, which EKF3 does not use, and the companion reads them as GPS2_RAW.
GPS1_ID, GPS2_ID = 0, 1
FEEDS = ("none", "gps-input", "vision")  # what ArduPilot flies on: EKF3 on the raw fixes, or the companion


@dataclass(frozen=True)
class ArduPilotConfig(ForeignFlightConfig):
    """How ArduCopter SITL is run, fed and flown (units in the names; the shared fields:
    ``ForeignFlightConfig``). ``gps_delay_ms`` is GPS1_DELAY_MS; ``gnss_rate_hz`` the GPS_INPUT rate."""

    speedup: float = 10.0  # SITL --speedup (measured stable at 10 on a loaded 2-core machine)

    def validate(self) -> None:
        super().validate()
        if not self.speedup > 0:
            raise ValueError(f"speedup: must be > 0, got {self.speedup!r}")
        if not 0 < self.gps_delay_ms <= 250:
            raise ValueError(f"gps_delay_ms: GPS1_DELAY_MS must be 1..250 ms, got {self.gps_delay_ms}")


# EKF3's pre-flight GPS quality checks (EK3_GPS_CHECK bits: NSats, HDoP, speed error, position error,
# yaw error, position drift, vertical speed, horizontal speed, vertical position error). The canyon
# receiver's honest single-point fixes fail them where the flights start (a street between buildings:
# vertical accuracy ~9 m > 7.5 m, speed accuracy ~1 m/s, the fix wandering 5-8 m at rest > 3 m), so EKF3
# never uses GNSS and the vehicle cannot take off; with the raw receiver every loop flies with them off.
CANYON_PARAMETERS = {"EK3_GPS_CHECK": 0}


def ardupilot_parameters(cfg: ArduPilotConfig, feed: str = "none", canyon: bool = False,
                         receiver_latency_ms: int | None = None) -> dict[str, float]:
    """The parameters of ``feed`` (:func:`_parameters`), with ``CANYON_PARAMETERS`` on the canyon receiver.
    ``receiver_latency_ms`` (the canyon receiver's): the closed loops' second receiver (the raw fixes the
    companion reads, which also set ArduPilot's clock) declares it as GPS2_DELAY_MS, as a user sets
    GPSn_DELAY_MS to a receiver's latency; the companion takes its clock lag from it."""
    params = _parameters(cfg, feed)
    if receiver_latency_ms is not None and "GPS2_DELAY_MS" in params:
        params["GPS2_DELAY_MS"] = receiver_latency_ms
    return {**params, **CANYON_PARAMETERS} if canyon else params


def _parameters(cfg: ArduPilotConfig, feed: str) -> dict[str, float]:
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
