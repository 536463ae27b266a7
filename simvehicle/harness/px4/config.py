"""Parameters of a flight beside PX4 SITL (SIH quadrotor): the ONE place their values live.

Where PX4's GNSS comes from (measured on the shared build, PX4 main of 2025-02): the SIH airframe
starts PX4's own GPS simulation (``sensor_gps_sim``) only when ``SENS_EN_GPSSIM`` is 1; with 0 it
has no GPS until one arrives over MAVLink. GPS_INPUT is not handled by this PX4's MAVLink
receiver; HIL_GPS is, when ``MAV_USEHILGPS`` is 1 and the sender's system id is the vehicle's
(``mavlink_receiver``: it then publishes ``sensor_gps`` with a MAVLink device id, stamped at
ARRIVAL: ``timestamp_sample`` 0, the message's ``time_usec`` kept only as UTC time). So our
degraded fixes reach EKF2 as HIL_GPS, the only GNSS it has, and EKF2 assumes each is
``EKF2_GPS_DELAY`` old (the SIH airframe sets 0 for its own delay-free GPS; we set our open-sky
latency, 100 ms, as ArduPilot's ``GPS1_DELAY_MS``). PX4's own GPS simulation is not used: its
errors are its own model (white noise and a random walk), not ours, and it cannot be driven by
an external model.
"""

from __future__ import annotations

from dataclasses import dataclass

from simvehicle.harness.foreign.config import ForeignFlightConfig

FEEDS = ("none", "odometry")  # what PX4 flies on: EKF2 on the raw fixes, or the companion's ODOMETRY
PX4_MODE_OFFBOARD = 6  # custom_mode main mode (custom_mode >> 16 & 0xff)
# EKF2_GPS_CTRL bits: 0 lon/lat, 1 altitude, 2 3-D velocity, 3 dual-antenna heading
GPS_CTRL_POSITION_ALTITUDE, GPS_CTRL_VELOCITY = 1 | 2, 4
# EKF2_EV_CTRL bits: 0 horizontal position, 1 vertical position, 2 velocity, 3 yaw
EV_CTRL_POSITION_YAW = 1 | 2 | 8  # no velocity (as ArduPilot's ExternalNav loop)
HGT_REF_VISION = 3  # EKF2_HGT_REF: 0 baro, 1 GPS, 2 range, 3 vision


@dataclass(frozen=True)
class Px4FlightConfig(ForeignFlightConfig):
    """How PX4 SITL is run, fed and flown (units in the names; the shared fields:
    ``ForeignFlightConfig``). ``gps_delay_ms`` is EKF2_GPS_DELAY; ``gnss_rate_hz`` the HIL_GPS rate;
    ``estimate_rate_hz`` LOCAL_POSITION_NED's."""

    speed_factor: float = 5.0  # PX4_SIM_SPEED_FACTOR (lockstep SIH; 4.9x measured on 2 cores, <= 10)
    offboard_warmup_s: float = 1.0  # setpoints streamed before OFFBOARD is asked for (PX4 needs them)
    connect_timeout_s: float = 30.0  # wall seconds for the first HEARTBEAT on the GCS link
    # closed loop: what EKF2 fuses of the companion's ODOMETRY (EKF2_EV_CTRL bits: 0 horizontal
    # position, 1 vertical position, 2 velocity, 3 yaw) and whether it takes the message's covariance
    # (EKF2_EV_NOISE_MD 0, PX4's default) or its EKF2_EVP_NOISE/EKF2_EVV_NOISE (1)
    ev_ctrl: int = EV_CTRL_POSITION_YAW
    ev_noise_md: int = 0
    ev_pos_noise_m: float | None = None  # EKF2_EVP_NOISE (None: PX4's default, 0.1 m)
    ulog: bool = False  # keep PX4's own ULog of the flight (px4/rootfs/log, about 15 MB per simulated minute)

    def validate(self) -> None:
        super().validate()
        if not 0 < self.speed_factor <= 10:
            raise ValueError(f"speed_factor: within (0, 10] (PX4's MAVLink output collapses above 10, "
                             f"measured on 2 cores), got {self.speed_factor!r}")
        if not 0 <= self.gps_delay_ms <= 300:
            raise ValueError(f"gps_delay_ms: EKF2_GPS_DELAY must be 0..300 ms, got {self.gps_delay_ms}")


# EKF2's GNSS quality checks (EKF2_GPS_CHECK bits: fix, satellites, PDOP, EPH, EPV, speed accuracy, drift,
# speeds): the canyon receiver's honest fixes where the flights start (horizontal ~3.6 m, vertical ~9 m,
# speed ~1 m/s, wandering at rest) exceed the defaults (EKF2_REQ_EPH 3 m, _EPV 5 m, _SACC 0.5 m/s), so
# with the raw receiver EKF2 flies with them off, as ArduPilot's EKF3 (EK3_GPS_CHECK 0).
CANYON_PARAMETERS = {"EKF2_GPS_CHECK": 0}


def px4_parameters(cfg: Px4FlightConfig, feed: str = "none", canyon: bool = False) -> dict[str, float]:
    """The parameters of ``feed`` (:func:`_parameters`), with ``CANYON_PARAMETERS`` on the canyon receiver."""
    params = _parameters(cfg, feed)
    return {**params, **CANYON_PARAMETERS} if canyon else params


def _parameters(cfg: Px4FlightConfig, feed: str) -> dict[str, float]:
    """Parameters set at boot (``px4-rc.params``, sourced after the airframe).

    Always: no simulated GPS of PX4's own (``SENS_EN_GPSSIM`` 0), HIL_GPS accepted
    (``MAV_USEHILGPS`` 1), ``EKF2_GPS_DELAY`` = our open-sky latency.

    Open loop (``none``): EKF2 fuses our raw fixes, position and altitude, and the Doppler velocity
    with ``gnss_velocity`` (``EKF2_GPS_CTRL`` 7, PX4's default; 3 without). Height keeps PX4's
    default reference, GNSS (``EKF2_HGT_REF`` 1), the barometer fused with a bias.

    Closed loop (``odometry``): EKF2 fuses no GNSS (``EKF2_GPS_CTRL`` 0) but the companion's
    ODOMETRY as external vision: horizontal and vertical position, velocity and yaw
    (``EKF2_EV_CTRL`` 15), and takes its height reference from it (``EKF2_HGT_REF`` 3). The raw
    fixes still reach PX4 (HIL_GPS), which streams them as GPS_RAW_INT to the companion.
    """
    common = {"SENS_EN_GPSSIM": 0, "MAV_USEHILGPS": 1, "EKF2_GPS_DELAY": cfg.gps_delay_ms}
    if feed == "odometry":
        noise = {} if cfg.ev_pos_noise_m is None else {"EKF2_EVP_NOISE": cfg.ev_pos_noise_m}
        return {**common, "EKF2_GPS_CTRL": 0, "EKF2_EV_CTRL": cfg.ev_ctrl,
                "EKF2_EV_NOISE_MD": cfg.ev_noise_md, **noise, "EKF2_HGT_REF": HGT_REF_VISION}
    velocity = GPS_CTRL_VELOCITY if cfg.gnss_velocity else 0
    return {**common, "EKF2_GPS_CTRL": GPS_CTRL_POSITION_ALTITUDE | velocity}
