"""Time scales: GPS time as ONE float, and explicit conversions to UTC/Unix, BDT, GLONASS and boot time.

``t_gps_s`` = seconds since the GPS epoch 1980-01-06 00:00:00 GPST (continuous, no leap seconds).
Its float64 resolution is 0.24 µs in the 2020s: a satellite moves < 1 mm in that time and the
receiver clock is estimated anyway, so one float is enough for every geometry here; a week and
seconds-of-week pair is available through :func:`week_tow` / :func:`gps_from_week_tow`.

Relations (IS-GPS-200, Galileo OS SIS ICD, BeiDou ICD, GLONASS ICD, RINEX 3.05 §3.1):

* GPST − UTC = the leap-second count (18 s since 2017-01-01; table below);
* Galileo GST = GPST (a RINEX file's GAL week is the GPS week);
* BDT = GPST − 14 s, BDT week 0 began 2006-01-01 (GPS week 1356);
* GLONASS time = UTC(SU) + 3 h; RINEX writes GLONASS epochs (``GLO`` time system) in UTC;
* Unix time (``time_unix_usec`` of MAVLink SYSTEM_TIME) counts UTC seconds since 1970 without
  leap seconds: ``unix = t_gps − gps_minus_utc + 315 964 800``.
"""

from __future__ import annotations

import calendar
from dataclasses import dataclass

import numpy as np

from companion.errors import UserError
from companion.gnss.constants import SECONDS_PER_WEEK

GPS_EPOCH_UNIX_S = 315_964_800  # 1980-01-06 00:00:00 UTC (GPST = UTC then)
GPS_MINUS_BDT_S = 14.0
BDT_WEEK_OFFSET = 1356  # GPS week of BDT week 0
GLONASS_MINUS_UTC_S = 3 * 3600.0

# (UTC date the offset takes effect, GPST − UTC from then on), IERS Bulletin C
_LEAP_DATES = (
    ((1981, 7, 1), 1),
    ((1982, 7, 1), 2),
    ((1983, 7, 1), 3),
    ((1985, 7, 1), 4),
    ((1988, 1, 1), 5),
    ((1990, 1, 1), 6),
    ((1991, 1, 1), 7),
    ((1992, 7, 1), 8),
    ((1993, 7, 1), 9),
    ((1994, 7, 1), 10),
    ((1996, 1, 1), 11),
    ((1997, 7, 1), 12),
    ((1999, 1, 1), 13),
    ((2006, 1, 1), 14),
    ((2009, 1, 1), 15),
    ((2012, 7, 1), 16),
    ((2015, 7, 1), 17),
    ((2017, 1, 1), 18),
)
# the same instants as Unix seconds and as GPS seconds
LEAP_UNIX_S = np.array([calendar.timegm((*d, 0, 0, 0)) for d, _ in _LEAP_DATES], dtype=float)
LEAP_COUNT_S = np.array([n for _, n in _LEAP_DATES], dtype=float)
LEAP_GPS_S = LEAP_UNIX_S - GPS_EPOCH_UNIX_S + LEAP_COUNT_S

SCALES = ("GPS", "GAL", "QZS", "BDT", "UTC", "GLO")


def gps_minus_utc_s(t_gps_s: float) -> float:
    """Leap seconds (GPST − UTC) in force at GPS time ``t_gps_s`` (0 before 1981-07-01)."""
    i = int(np.searchsorted(LEAP_GPS_S, t_gps_s, side="right"))
    return float(LEAP_COUNT_S[i - 1]) if i else 0.0


def gps_minus_utc_at_unix_s(t_unix_s: float) -> float:
    """Leap seconds (GPST − UTC) in force at UTC Unix time ``t_unix_s``."""
    i = int(np.searchsorted(LEAP_UNIX_S, t_unix_s, side="right"))
    return float(LEAP_COUNT_S[i - 1]) if i else 0.0


def gps_to_unix_s(t_gps_s: float) -> float:
    """GPS time -> UTC Unix seconds (what MAVLink SYSTEM_TIME.time_unix_usec counts, in s)."""
    return t_gps_s - gps_minus_utc_s(t_gps_s) + GPS_EPOCH_UNIX_S


def unix_to_gps_s(t_unix_s: float) -> float:
    """UTC Unix seconds -> GPS time."""
    return t_unix_s - GPS_EPOCH_UNIX_S + gps_minus_utc_at_unix_s(t_unix_s)


def gps_from_week_tow(week: int, tow_s: float) -> float:
    return week * float(SECONDS_PER_WEEK) + tow_s


def week_tow(t_gps_s: float) -> tuple[int, float]:
    """(GPS week, seconds of week) of ``t_gps_s``."""
    week = int(t_gps_s // SECONDS_PER_WEEK)
    return week, t_gps_s - week * float(SECONDS_PER_WEEK)


def bdt_to_gps_s(t_bdt_s: float) -> float:
    """BeiDou time as seconds since the BDT epoch (2006-01-01) -> GPS time."""
    return t_bdt_s + BDT_WEEK_OFFSET * float(SECONDS_PER_WEEK) + GPS_MINUS_BDT_S


def gps_to_bdt_s(t_gps_s: float) -> float:
    return t_gps_s - BDT_WEEK_OFFSET * float(SECONDS_PER_WEEK) - GPS_MINUS_BDT_S


def gps_from_calendar(
    year: int, month: int, day: int, hour: int, minute: int, second: float, scale: str = "GPS"
) -> float:
    """A calendar date read in time scale ``scale`` (``SCALES``) -> GPS time.

    ``GLO`` is UTC as RINEX writes GLONASS epochs; Moscow time (UTC + 3 h, the GLONASS navigation
    message's own) is :data:`GLONASS_MINUS_UTC_S` away and is the caller's to remove."""
    if not (
        1980 <= year <= 2200
        and 1 <= month <= 12
        and 1 <= day <= 31
        and 0 <= hour < 24
        and 0 <= minute < 60
        and 0 <= second < 61
    ):
        raise UserError(f"date {year}-{month}-{day} {hour}:{minute}:{second} out of range")
    whole = calendar.timegm((year, month, day, hour, minute, 0)) - GPS_EPOCH_UNIX_S
    t = whole + float(second)  # seconds since 1980-01-06 in the calendar's own scale
    if scale in ("GPS", "GAL", "QZS"):
        return t
    if scale == "BDT":
        return t + GPS_MINUS_BDT_S
    if scale in ("UTC", "GLO"):
        return t + gps_minus_utc_at_unix_s(t + GPS_EPOCH_UNIX_S)
    raise UserError(f"unknown time system {scale!r} (known: {', '.join(SCALES)})")


def resolve_week(week_mod: int, modulus: int, t_ref_gps_s: float) -> int:
    """Full GPS week from a truncated one (LNAV: 10 bits, modulus 1024; CNAV 13 bits) closest to
    the reference time ``t_ref_gps_s`` (e.g. the receiver's clock or the log's date)."""
    ref_week = t_ref_gps_s / SECONDS_PER_WEEK
    k = round((ref_week - week_mod) / modulus)
    return int(week_mod + k * modulus)


def wrap_week_s(dt_s: np.ndarray | float) -> np.ndarray | float:
    """A time difference brought into [−302 400, 302 400) s (IS-GPS-200 20.3.3.4.3 tk)."""
    half = SECONDS_PER_WEEK / 2
    return (np.asarray(dt_s) + half) % SECONDS_PER_WEEK - half


@dataclass(frozen=True)
class BootTimeMap:
    """Vehicle boot time <-> GPS time, fitted to (UTC Unix µs, boot µs) pairs such as a log's
    SYSTEM_TIME (``time_unix_usec``, ``time_boot_ms``) or (GPS time, boot time) pairs.

    ``boot_us = offset_us + (1 + drift) · (t_gps_s · 1e6)``: a least-squares line through the pairs
    that agree with their median offset within ``tolerance_us`` (the others — a clock not yet set,
    a stamp that jumped — are counted in ``rejected``)."""

    offset_us: float  # boot µs at t_gps = 0 (extrapolated)
    drift: float  # boot-clock rate error (dimensionless)
    pairs_used: int
    rejected: int
    residual_rms_us: float
    t_gps_first_s: float
    t_gps_last_s: float

    @classmethod
    def from_gps_pairs(
        cls, t_gps_s: np.ndarray, boot_us: np.ndarray, tolerance_us: float = 50_000.0
    ) -> BootTimeMap:
        t_gps_s = np.asarray(t_gps_s, dtype=float)
        boot_us = np.asarray(boot_us, dtype=float)
        ok = np.isfinite(t_gps_s) & np.isfinite(boot_us) & (t_gps_s > 0)
        if not ok.any():
            raise UserError("no usable (GPS or Unix time, boot time) pairs to join the time bases")
        off = boot_us[ok] - t_gps_s[ok] * 1e6
        keep = np.abs(off - np.median(off)) <= tolerance_us
        t, b = t_gps_s[ok][keep], boot_us[ok][keep]
        t0 = float(t[0])
        if len(t) >= 2 and t[-1] - t[0] > 10.0:
            slope, icpt = np.polyfit(t - t0, b, 1)  # boot µs per GPS s
            drift = slope / 1e6 - 1.0
        else:
            drift, icpt = 0.0, float(np.median(b - (t - t0) * 1e6))
        offset = icpt - (1.0 + drift) * t0 * 1e6
        res = b - (offset + (1.0 + drift) * t * 1e6)
        return cls(
            float(offset),
            float(drift),
            int(len(t)),
            int(ok.sum() - len(t) + (~ok).sum()),
            float(np.sqrt(np.mean(res**2))),
            t0,
            float(t[-1]),
        )

    @classmethod
    def from_system_time(
        cls, time_unix_us: np.ndarray, time_boot_us: np.ndarray, tolerance_us: float = 50_000.0
    ) -> BootTimeMap:
        """From SYSTEM_TIME pairs (``time_unix_usec``, ``time_boot_ms * 1000``); Unix 0 (clock not
        set) is dropped. Leap seconds from the table at each stamp."""
        unix_us = np.asarray(time_unix_us, dtype=float)
        set_ = unix_us > 1e15  # after 2001: a clock that was set
        t_gps = np.full(unix_us.shape, np.nan)
        t_gps[set_] = [unix_to_gps_s(u / 1e6) for u in unix_us[set_]]
        return cls.from_gps_pairs(t_gps, np.asarray(time_boot_us, dtype=float), tolerance_us)

    def boot_us(self, t_gps_s: float) -> int:
        return int(round(self.offset_us + (1.0 + self.drift) * t_gps_s * 1e6))

    def gps_s(self, boot_us: float) -> float:
        return (boot_us - self.offset_us) / ((1.0 + self.drift) * 1e6)
