"""The autopilot's messages as estimator samples on ONE time base: the autopilot's boot time (µs).

Sources (one of each kind is used; when a better-ranked source appears the others are counted
as ``*_other_source`` and not fed twice):

- IMU: HIGHRES_IMU (SI units, ``time_usec`` boot µs) > SCALED_IMU > RAW_IMU > SCALED_IMU2.
  SCALED_IMU* carry acceleration in mG (1 g = 9.80665 m/s²) and rates in mrad/s, stamped
  ``time_boot_ms``. RAW_IMU is read in ArduPilot's units, which are the same mG and mrad/s
  (measured on ArduCopter SITL: ``zacc = -1001`` at rest; ``time_usec`` boot µs); on PX4
  RAW_IMU is raw sensor counts, so a PX4 companion must use HIGHRES_IMU (PX4 streams it).
- Attitude: ATTITUDE_QUATERNION (``q1`` = w, body FRD -> NED) > ATTITUDE (Euler ZYX).
- GNSS: GPS_RAW_INT (receiver 1) or GPS2_RAW (receiver 2), chosen by ``gnss_instance``, with the
  receiver's horizontal velocity (``vel``/``cog``, ``vel_acc``); or a fix another component hands
  the autopilot on the same link, GPS_INPUT or HIL_GPS (``gnss_message``), with its NED velocity.

GNSS time: ArduPilot stamps GPS_RAW_INT ``time_usec`` with the boot time at which its GPS driver
took the fix in (``last_fix_time_ms`` x 1000): an ARRIVAL time, not the receiver's validity
time; its own EKF3 subtracts ``GPS1_DELAY_MS`` (0 = the driver's default lag) to get the
validity time. We do the same with ``gnss_delay_us``: the option if given, else the autopilot's own
setting, read as a parameter (:data:`DELAY_PARAMS`: ArduPilot ``GPS1_DELAY_MS``/``GPS2_DELAY_MS``,
where 0 means its driver's default, :data:`ARDUPILOT_DEFAULT_GPS_DELAY_MS`; PX4 ``EKF2_GPS_DELAY``).
A stamp above :data:`UNIX_STAMP_MIN_US` is UNIX time (MAVLink allows either)
and is mapped to boot time with the SYSTEM_TIME pairs' offset. A fix repeated at the same stamp
(the autopilot streams GPS_RAW_INT faster than the receiver updates) is dropped and counted.

What the autopilot tells us about time and delay is checked before it is believed:

- SYSTEM_TIME: a UNIX time outside 2015..2100 is refused (``rejected_system_time_range``); the
  UNIX time is a stamped stream like any other and follows the project's clock rule
  (:data:`UNIX_CLOCK`, :mod:`companion.domain.clock_guard`) against the pair's own boot time
  (already checked): it may not run faster than the boot time (a sped-up PX4 SITL's UNIX clock
  runs at wall speed, slower than its boot time; real hardware: both at 1x). A lone pair far from
  the stream (an hour ahead, a second back) is refused (``rejected_system_time_clock``); three
  agreeing pairs over 1.5 s of boot time make a new time base (the autopilot's clock was set).
  The offset of the last accepted pair maps UNIX stamps.
- The receiver delay parameter: a value outside the autopilot's own range for it
  (:data:`DELAY_RANGES_MS`: ArduPilot ``GPSn_DELAY_MS`` 0..250 ms, PX4 ``EKF2_GPS_DELAY`` 0..300 ms)
  is refused (``rejected_gnss_delay_range``) and the default kept. Whether a PARAM_VALUE was
  asked for at all is the node's check (an unsolicited one is never adopted).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any

from companion.domain.clock_guard import ClockWindow, StreamClock, Verdict
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
from companion.mavlink import codec as mc

ARDUPILOT_DEFAULT_GPS_DELAY_MS = 120.0  # AP_GPS_UBLOX::get_lag, used by EKF3 when GPSn_DELAY_MS = 0
PX4_DEFAULT_GPS_DELAY_MS = 110.0  # EKF2_GPS_DELAY's default
# autopilot type -> receiver instance -> parameter holding the receiver delay (ms)
DELAY_PARAMS = {3: {1: "GPS1_DELAY_MS", 2: "GPS2_DELAY_MS"}, 12: {1: "EKF2_GPS_DELAY", 2: "EKF2_GPS_DELAY"}}
# autopilot type -> the receiver delay parameter's own range (ms): ArduPilot GPS_DELAY_MS, PX4 EKF2_GPS_DELAY
DELAY_RANGES_MS = {3: (0.0, 250.0), 12: (0.0, 300.0)}
UNIX_STAMP_MIN_US = 10**15  # ≈ 31.7 years: a larger stamp is UNIX time, not time since boot
UNIX_PLAUSIBLE_US = (1_420_070_400 * 10**6, 4_102_444_800 * 10**6)  # 2015-01-01 .. 2100-01-01 (UTC)
# SYSTEM_TIME's UNIX time against its boot time ("arrivals"): 1 s back, 1 s ahead of an envelope
# growing as fast as the boot time (+5 %); a new base needs 3 agreeing pairs over 1.5 s of boot time
UNIX_CLOCK = ClockWindow(max_back_us=1_000_000, max_forward_us=1_000_000, consensus_samples=3,
                         consensus_step_us=30_000_000, consensus_back_us=1_000_000, max_rate=1.05,
                         consensus_span_us=1_500_000)
IMU_RANK = {"HIGHRES_IMU": 0, "SCALED_IMU": 1, "RAW_IMU": 2, "SCALED_IMU2": 3}
ATTITUDE_RANK = {"ATTITUDE_QUATERNION": 0, "ATTITUDE": 1}
GNSS_TYPES = {1: "GPS_RAW_INT", 2: "GPS2_RAW"}
_DECODERS = {
    "HIGHRES_IMU": mc.decode_imu, "SCALED_IMU": mc.decode_scaled_imu, "RAW_IMU": mc.decode_raw_imu,
    "SCALED_IMU2": mc.decode_scaled_imu, "ATTITUDE_QUATERNION": mc.decode_attitude,
    "ATTITUDE": mc.decode_attitude_euler,
}


@dataclass(frozen=True, slots=True)
class TranslateConfig:
    gnss_instance: int = 1  # 1: GPS_RAW_INT, 2: GPS2_RAW
    gnss_delay_us: int | None = None  # receiver delay (validity = stamp - this); None: the autopilot's
    # the GNSS message read instead of the instance's (GPS_INPUT, HIL_GPS: fixes handed to the
    # autopilot by another component, seen on the link); None: the instance's
    gnss_message: str | None = None

    @property
    def gnss_type(self) -> str:
        return self.gnss_message or GNSS_TYPES[self.gnss_instance]


def boot_stamp_us(msg: Any) -> int | None:
    """The autopilot boot time a message is stamped with (µs), None if it carries none."""
    t_ms = getattr(msg, "time_boot_ms", None)
    if t_ms is not None:
        return int(t_ms) * 1000
    if msg.get_type() in IMU_RANK:  # HIGHRES_IMU / RAW_IMU: time_usec since boot
        return int(msg.time_usec)
    return None


@dataclass(slots=True)
class Translator:
    config: TranslateConfig = field(default_factory=TranslateConfig)
    counters: Counter[str] = field(default_factory=Counter)
    unix_minus_boot_us: int | None = None  # from SYSTEM_TIME
    last_attitude: AttitudeSample | None = None
    last_imu: ImuSample | None = None
    last_fix: GnssFix | None = None  # as received (stamp = arrival), after the time mapping
    gnss_delay_us: int = 0  # in force (set_gnss_delay)
    gnss_delay_source: str = "none"
    _imu_rank: int = len(IMU_RANK)
    _attitude_rank: int = len(ATTITUDE_RANK)
    _last_gnss_stamp_us: int = -1
    _unix: StreamClock = field(default_factory=lambda: StreamClock(UNIX_CLOCK))

    def __post_init__(self) -> None:
        if self.config.gnss_instance not in GNSS_TYPES:
            raise ValueError(f"gnss_instance must be 1 or 2, got {self.config.gnss_instance}")
        if self.config.gnss_message not in (None, *mc.GNSS_DECODERS):
            raise ValueError(f"gnss_message must be one of {', '.join(mc.GNSS_DECODERS)}, "
                             f"got {self.config.gnss_message}")
        if self.config.gnss_delay_us is not None:
            self.set_gnss_delay(self.config.gnss_delay_us, "option")

    def set_gnss_delay(self, delay_us: int, source: str) -> None:
        self.gnss_delay_us, self.gnss_delay_source = int(delay_us), source

    def delay_parameter(self, autopilot_type: int) -> str | None:
        """The autopilot's parameter to read the receiver delay from (None: option given, or unknown);
        meanwhile that autopilot's default delay is in force."""
        if self.config.gnss_delay_us is not None:
            return None
        if autopilot_type == 3:
            self.set_gnss_delay(round(ARDUPILOT_DEFAULT_GPS_DELAY_MS * 1000), "ArduPilot default, until read")
        elif autopilot_type == 12:
            self.set_gnss_delay(round(PX4_DEFAULT_GPS_DELAY_MS * 1000), "PX4 default, until read")
        return DELAY_PARAMS.get(autopilot_type, {}).get(self.config.gnss_instance)

    def delay_parameter_value(self, autopilot_type: int, name: str, value_ms: float) -> bool:
        """Take the autopilot's receiver-delay parameter (ArduPilot: 0 = its driver's default);
        False (counted, the delay in force kept) when it is outside the parameter's own range."""
        lo, hi = DELAY_RANGES_MS.get(autopilot_type, (0.0, 1000.0))
        if not lo <= value_ms <= hi:
            self.counters["rejected_gnss_delay_range"] += 1
            return False
        if autopilot_type == 3 and value_ms == 0:
            self.set_gnss_delay(round(ARDUPILOT_DEFAULT_GPS_DELAY_MS * 1000),
                                f"{name} = 0: ArduPilot's driver default")
        else:
            self.set_gnss_delay(round(value_ms * 1000), f"autopilot parameter {name}")
        return True

    def system_time(self, msg: Any) -> None:
        """A SYSTEM_TIME pair (its boot time already checked by the caller's clock rule)."""
        unix_us = int(msg.time_unix_usec)
        if unix_us <= UNIX_STAMP_MIN_US:  # no UNIX time yet (ArduPilot before its GPS has time)
            return
        if not UNIX_PLAUSIBLE_US[0] <= unix_us <= UNIX_PLAUSIBLE_US[1]:
            self.counters["rejected_system_time_range"] += 1
            return
        verdict = self._unix.check(unix_us, int(msg.time_boot_ms) * 1000)
        if verdict is Verdict.REJECT:
            self.counters["rejected_system_time_clock"] += 1
            return
        if verdict is Verdict.RESET:
            self.counters["system_time_clock_set"] += 1
        self.unix_minus_boot_us = unix_us - int(msg.time_boot_ms) * 1000

    def reset(self) -> None:
        """Forget the time-base state (after an autopilot reboot); source choices are kept."""
        self._last_gnss_stamp_us = -1
        self.unix_minus_boot_us = None
        self._unix.reset()
        self.last_attitude = self.last_imu = self.last_fix = None

    def sample(self, msg: Any) -> ImuSample | AttitudeSample | GnssFix | None:
        """The estimator sample in ``msg`` (None for other messages or a counted rejection)."""
        kind = msg.get_type()
        if kind == self.config.gnss_type:
            return self._gnss(msg)
        if kind in IMU_RANK:
            rank = IMU_RANK[kind]
            if rank > self._imu_rank:
                self.counters["imu_other_source"] += 1
                return None
            self._imu_rank = rank
        elif kind in ATTITUDE_RANK:
            rank = ATTITUDE_RANK[kind]
            if rank > self._attitude_rank:
                self.counters["attitude_other_source"] += 1
                return None
            self._attitude_rank = rank
        else:
            return None
        try:
            sample = _DECODERS[kind](msg)
        except mc.CodecError as exc:
            self.counters[f"rejected_{kind.lower()}_{exc.reason}"] += 1
            return None
        if isinstance(sample, ImuSample):
            self.last_imu = sample
        elif isinstance(sample, AttitudeSample):
            self.last_attitude = sample
        return sample  # type: ignore[return-value]

    def _gnss(self, msg: Any) -> GnssFix | None:
        stamp_us = int(msg.time_usec)
        if stamp_us == 0:  # ArduPilot before its first fix
            self.counters["gnss_no_stamp"] += 1
            return None
        if stamp_us == self._last_gnss_stamp_us:
            self.counters["gnss_repeated"] += 1
            return None
        self._last_gnss_stamp_us = stamp_us
        if stamp_us > UNIX_STAMP_MIN_US:
            if self.unix_minus_boot_us is None:
                self.counters["gnss_no_time_base"] += 1
                return None
            stamp_us -= self.unix_minus_boot_us
        try:
            fix = mc.GNSS_DECODERS[msg.get_type()](msg)
        except mc.CodecError as exc:
            self.counters[f"rejected_gnss_{exc.reason}"] += 1
            return None
        fix = replace(fix, t_validity_us=stamp_us - self.gnss_delay_us)
        self.last_fix = fix
        return fix
