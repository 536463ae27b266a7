"""What the tightly coupled navigator takes beside the IMU and attitude samples (boot-time stamped)."""

from __future__ import annotations

from dataclasses import dataclass

from companion.gnss.observations import GnssEpoch


@dataclass(frozen=True, slots=True, eq=False)
class RawGnss:
    """One receiver epoch of raw observations, measured at boot time ``t_us`` (its receiver time tag
    mapped to the vehicle's clock: ``companion.gnss.timescale.BootTimeMap``)."""

    t_us: int
    epoch: GnssEpoch


@dataclass(frozen=True, slots=True)
class Odometry:
    """A ground vehicle's wheel odometry: forward speed and heading rate (about the body's down axis,
    clockwise seen from above: the rate of the NED yaw). Speed NaN: a gyro's yaw rate alone (no wheel
    speed): the filter then knows the heading's turns and that the vehicle does not slide sideways."""

    t_us: int
    speed_m_s: float
    yaw_rate_rad_s: float
