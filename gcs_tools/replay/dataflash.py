"""ArduPilot DataFlash ``.bin`` -> replay events, streamed.

The log is scanned in blocks (memory flat in its length; pymavlink's ``DFReader`` maps the file
and indexes every message first, which grows with the log). Message layouts come from the log's
own FMT messages through pymavlink's ``DFReader.DFFormat`` (struct layout and the scale of each
format character, e.g. ``L`` = 1e-7 degrees, ``e`` = centi-units). Fields are read by name;
a message whose FMT lacks a needed field ends the replay with a one-line error naming both.

What is used (instance/core 0 where a message has several):

- ``IMU`` (``TimeUS``, ``GyrX..Z`` rad/s, ``AccX..Z`` m/s², body FRD): one ImuSample each.
- ``BARO`` (``Alt``, m above the barometer's ground calibration; instance 0): carried by the next IMU
  sample (``ImuSample.pressure_alt_m``: the tight filter's barometer; the loose filter has none).
- ``ATT`` (``Roll``, ``Pitch``, ``Yaw`` in degrees): the AHRS attitude the autopilot flies
  with (the DataFlash twin of MAVLink ATTITUDE) -> AttitudeSample.
- ``GPS`` (``Status`` = fix type, ``Lat``/``Lng`` degrees, ``Alt`` m MSL, ``NSats``, ``HDop``;
  velocity from ``Spd`` m/s, ``GCrs`` degrees from north, ``VZ`` m/s down) with its ``GPA``
  (``HAcc``/``VAcc`` m, ``SMS`` = the ms boot time the fix was received, ``SAcc`` speed accuracy
  m/s, ``VV`` 0 when the receiver has no vertical velocity).
  Validity time = ``GPA.SMS`` − the GPS delay (``GPS.TimeUS`` when no GPA follows); the delay is
  the log's ``GPS1_DELAY_MS`` (or ``GPS_DELAY_MS``, or ArduCopter <= 3.2's ``EKF_POS_DELAY``)
  when it is set (> 0), else :data:`DEFAULT_GPS_DELAY_MS` (:data:`OLD_DEFAULT_GPS_DELAY_MS` for a
  log whose GPS has no ``TimeUS``), or the caller's value.

Old logs (ArduCopter <= 3.2) stamp in milliseconds: ``TimeMS`` instead of ``TimeUS`` (read as
µs = ms × 1000) in IMU, ATT, SIM; their GPS's ``TimeMS`` is the GPS time of week, so its boot
time is ``T`` (ms); a GPS with neither (before 3.2) is stamped when it arrives (the latest IMU
or ATT time, counted ``gnss_stamped_on_arrival``, as pymavlink's DFReader does). They have no GPA,
POS, XKF1 or ORGN: no accuracies and no autopilot estimate. Which field was read for each is in
``DataFlashScanner.resolved``; a message lacking every alternative of a needed field ends the
replay in one line naming them (``IMU has no field TimeUS or TimeMS``).
- The autopilot's estimate: ``POS`` (``Lat``, ``Lng``, ``Alt`` MSL) or, when the log has none,
  ``XKF1`` (EKF3) / ``NKF1`` (EKF2) core 0 (``PN``/``PE``/``PD`` about the EKF origin of ``ORGN``
  ``Type`` 0): both geodetic, so no offset is fitted.
- Truth (SITL): ``SIM`` (``Lat``, ``Lng``, ``Alt``).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d
from pymavlink.DFReader import DFFormat

from companion.autopilot.translate import ARDUPILOT_DEFAULT_GPS_DELAY_MS
from companion.domain.rotation import euler_to_quaternion
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
from companion.errors import UserError
from companion.mavlink.codec import LIMITS
from gcs_tools.replay.events import (
    AUTOPILOT,
    MIN_FIX_TYPE_3D,
    TRUTH,
    Event,
    ReaderStats,
    Reference,
    ReferenceInfo,
)

HEAD = b"\xa3\x95"
FMT_TYPE = 128
FMT_LAYOUT = struct.Struct("<BB4s16s64s")  # Type, Length, Name, Format, Columns
READ_BLOCK = 1 << 20
MAX_MESSAGE = 3 + 255
# ArduPilot's lag for a u-blox M8-class receiver when GPS*_DELAY_MS is 0 (the live adapter's constant);
# on the SITL log in tests/data the fix that fits truth best is ~85 ms old (SIM_GPS1_LAG_MS 100).
DEFAULT_GPS_DELAY_MS = ARDUPILOT_DEFAULT_GPS_DELAY_MS
DELAY_PARAMS = ("GPS1_DELAY_MS", "GPS_DELAY_MS", "EKF_POS_DELAY")  # the last: ArduCopter <= 3.2's EKF
OLD_DEFAULT_GPS_DELAY_MS = 220.0  # EKF_POS_DELAY's default in ArduCopter <= 3.2 (NavEKF)



@dataclass(frozen=True)
class Field:
    """A value read from a message: the first of ``names`` its FMT has, times ``factor`` (after the
    format's own scale); ``optional``: NaN when none is there (else a one-line error)."""

    names: tuple[str, ...]
    factors: tuple[float, ...] = ()
    optional: bool = False

    def alternatives(self) -> Iterator[tuple[str, float]]:
        for k, name in enumerate(self.names):
            yield name, self.factors[k] if k < len(self.factors) else 1.0


def _f(*names: str, optional: bool = False) -> Field:
    return Field(names, optional=optional)


# microseconds of boot time: TimeUS, or TimeMS (ArduPilot <= 3.2) in ms
TIME_US = Field(("TimeUS", "TimeMS"), (1.0, 1000.0))
# GPS boot time: TimeUS, or T in ms (3.2: its TimeMS is the GPS time of week, not boot time);
# older GPS have neither (then the fix is stamped on arrival)
GPS_TIME_US = Field(("TimeUS", "T"), (1.0, 1000.0), optional=True)
FIELDS: dict[str, tuple[Field, ...]] = {
    "IMU": (TIME_US, *(_f(n) for n in ("GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ"))),
    "ATT": (TIME_US, _f("Roll"), _f("Pitch"), _f("Yaw")),
    "GPS": (GPS_TIME_US, *(_f(n) for n in ("Status", "NSats", "HDop", "Lat", "Lng", "Alt")),
            *(_f(n, optional=True) for n in ("Spd", "GCrs", "VZ"))),
    "GPA": (TIME_US, _f("HAcc"), _f("VAcc"), _f("SMS"), _f("SAcc", optional=True), _f("VV", optional=True)),
    "POS": (TIME_US, _f("Lat"), _f("Lng"), _f("Alt")),
    "XKF1": (TIME_US, _f("PN"), _f("PE"), _f("PD")),
    "NKF1": (TIME_US, _f("PN"), _f("PE"), _f("PD")),
    "ORGN": (_f("Type"), _f("Lat"), _f("Lng"), _f("Alt")),
    "SIM": (TIME_US, _f("Lat"), _f("Lng"), _f("Alt")),
    "PARM": (_f("Name"), _f("Value")),
    # the barometer's height above its ground calibration (m; ArduPilot's datum): on the next IMU sample
    "BARO": (TIME_US, _f("Alt")),
}
REQUIRED = frozenset({"IMU", "ATT", "GPS"})  # the estimator's inputs; the rest only adds comparisons
INSTANCE_FIELD = {"IMU": "I", "GPS": "I", "GPA": "I", "XKF1": "C", "NKF1": "C", "BARO": "I"}
INFO = {
    "POS": ReferenceInfo("POS", "geodetic", "estimated position vs the autopilot's POS (lat, lon, alt MSL) "
                         "converted into the replay's frame"),
    "XKF1": ReferenceInfo("XKF1+ORGN", "geodetic", "estimated position vs EKF3 core 0 (XKF1 PN/PE/PD about "
                          "the EKF origin of ORGN, converted into the replay's frame)"),
    "NKF1": ReferenceInfo("NKF1+ORGN", "geodetic", "estimated position vs EKF2 core 0 (NKF1 PN/PE/PD about "
                          "the EKF origin of ORGN, converted into the replay's frame)"),
    "SIM": ReferenceInfo("SIM", "geodetic", "estimated position vs SITL truth (SIM lat, lon, alt)"),
}


class _Layout:
    """How to unpack one message type: the wanted fields' indices and scales (``None``: an
    optional field the message does not have, read as NaN)."""

    def __init__(self, fmt: DFFormat, wanted: tuple[Field, ...], path: Path) -> None:
        self.struct = struct.Struct(fmt.msg_struct)
        self.length = fmt.len
        index: list[int | None] = []
        factor: list[float] = []
        self.names: list[str | None] = []
        for field in wanted:
            found = next(((fmt.colhash[n], f, n) for n, f in field.alternatives() if n in fmt.colhash), None)
            if found is None and not field.optional:
                raise UserError(f"{path}: DataFlash message {fmt.name} has no field "
                                f"{' or '.join(field.names)} (its fields: {','.join(fmt.columns)})")
            index.append(None if found is None else found[0])
            factor.append(1.0 if found is None else found[1])
            self.names.append(None if found is None else found[2])
        self.index = tuple(index)
        # scaled as DFReader does: divide by 1/m for m < 1 (1e-7 degrees, centi-units: exact
        # decimal results), multiply otherwise; then the unit factor (ms -> µs)
        mults = [None if i is None else fmt.msg_mults[i] for i in self.index]
        self.divisor = tuple(None if m is None else 1 / m for m in mults)
        self.multiplier = tuple(None if m is None or 0 < m < 1 else m for m in mults)
        self.factor = tuple(factor)
        inst = INSTANCE_FIELD.get(fmt.name)
        self.instance = fmt.colhash.get(inst) if inst else None

    def values(self, raw: tuple[Any, ...]) -> list[Any]:
        out = []
        for i, d, m, f in zip(self.index, self.divisor, self.multiplier, self.factor, strict=True):
            if i is None:
                out.append(math.nan)
                continue
            v = raw[i]
            v = v if d is None else v * m if m is not None else v / d
            out.append(v if f == 1.0 else v * f)
        return out


class DataFlashScanner:
    """Stream ``(name, values)`` of the wanted message types (values in FIELDS order, scaled),
    instance/core 0 only. Counts unreadable spans in ``stats.skipped`` by reason."""

    def __init__(self, path: Path, wanted: Iterable[str], stats: ReaderStats) -> None:
        self.path, self.wanted, self.stats = path, frozenset(wanted), stats
        self.resolved: dict[str, list[str | None]] = {}  # message -> the field read for each of FIELDS'

    def __iter__(self) -> Iterator[tuple[str, list[Any]]]:
        st = self.stats
        st.size = self.path.stat().st_size
        lengths: dict[int, int] = {FMT_TYPE: 89}
        layouts: dict[int, tuple[str, _Layout]] = {}
        with open(self.path, "rb") as f:
            data, base, pos, eof = b"", 0, 0, False
            lost_at, lost_reason = -1, ""
            while True:
                if not eof and len(data) - pos < MAX_MESSAGE:
                    block = f.read(READ_BLOCK)
                    eof = len(block) < READ_BLOCK
                    data, base, pos = data[pos:] + block, base + pos, 0
                    st.position = base
                n = len(data)
                if pos >= n:
                    break
                mtype = data[pos + 2] if pos + 2 < n else -1
                length = lengths.get(mtype, 0) if data[pos : pos + 2] == HEAD else 0
                if length == 0 or pos + length > n:
                    reason = "truncated" if length and eof else "garbage" if not length else ""
                    if not reason:
                        continue
                    if lost_at < 0:
                        lost_at, lost_reason = base + pos, reason
                    nxt = data.find(HEAD, pos + 1)
                    pos = nxt if nxt >= 0 else max(pos + 1, n - 1)
                    continue
                if lost_at >= 0:
                    self._skip(lost_reason, base + pos - lost_at)
                    lost_at = -1
                st.records += 1
                if mtype == FMT_TYPE:
                    self._define(data, pos, lengths, layouts)
                else:
                    entry = layouts.get(mtype)
                    if entry is not None:
                        name, layout = entry
                        raw = layout.struct.unpack_from(data, pos + 3)
                        if layout.instance is None or raw[layout.instance] == 0:
                            yield name, layout.values(raw)
                pos += length
        if lost_at >= 0:
            self._skip(lost_reason, st.size - lost_at)
        st.position = st.size

    def _skip(self, reason: str, size: int) -> None:
        self.stats.skipped[reason] += 1
        self.stats.skipped_bytes += size

    def _define(
        self, data: bytes, pos: int, lengths: dict[int, int], layouts: dict[int, tuple[str, _Layout]]
    ) -> None:
        mtype, mlen, name_b, fmt_b, cols_b = FMT_LAYOUT.unpack_from(data, pos + 3)
        name = name_b.rstrip(b"\0").decode("ascii", "replace")
        if mlen < 3:
            self.stats.rejected["fmt_bad_length"] += 1
            return
        lengths[mtype] = mlen
        if name not in self.wanted:
            layouts.pop(mtype, None)
            return
        try:
            fmt = DFFormat(mtype, name, mlen, fmt_b.rstrip(b"\0").decode("ascii"),
                           cols_b.rstrip(b"\0").decode("ascii"))
        except Exception:  # noqa: BLE001 - DFFormat raises a bare Exception on an unknown format char
            layout = fmt_b.rstrip(b"\0")
            raise UserError(f"{self.path}: DataFlash FMT of {name} has an unknown format "
                            f"{layout!r}") from None
        if struct.calcsize(fmt.msg_struct) + 3 != mlen:
            self.stats.rejected["fmt_length_mismatch"] += 1
            return
        try:
            layouts[mtype] = (name, _Layout(fmt, FIELDS[name], self.path))
            self.resolved[name] = layouts[mtype][1].names
        except UserError:
            if name in REQUIRED:
                raise
            # an optional message (references, GPA, parameters) this reader cannot read: counted
            self.stats.rejected[f"{name.lower()}_unknown_layout"] += 1


class DataFlashSource:
    format = "dataflash"
    anchor = None  # home: the first 3-D fix

    def __init__(self, path: Path, gps_delay_ms: float | None = None) -> None:
        self.path = path
        self.stats = ReaderStats()
        self.sources: dict[str, str | None] = {"imu": "IMU", "attitude": "ATT", "gnss": "GPS+GPA"}
        self.references: dict[str, ReferenceInfo] = {}
        self.gps_delay_ms = gps_delay_ms
        self.gps_delay_source = "option" if gps_delay_ms is not None else ""

    def first_fix(self) -> GnssFix | None:
        for name, v in DataFlashScanner(self.path, ("GPS",), ReaderStats()):
            if name == "GPS" and v[1] >= MIN_FIX_TYPE_3D:
                fix = _fix([0 if math.isnan(v[0]) else v[0], *v[1:]], None, 0.0)
                if fix is not None:
                    return fix
        return None

    def describe_empty(self) -> str:
        st = ReaderStats()
        n = sum(1 for _ in DataFlashScanner(self.path, ("GPS",), st))
        if st.records == 0:
            return f"no readable DataFlash messages{_skips(st)}"
        return f"no usable GPS 3-D fix (Status >= 3) in {n} GPS of {st.records} messages{_skips(st)}"

    def __iter__(self) -> Iterator[Event]:
        st = self.stats
        decoded, rejected = st.decoded, st.rejected
        params: dict[str, float] = {}
        delay_us: float | None = None if self.gps_delay_ms is None else self.gps_delay_ms * 1000
        pending_gps: list[Any] | None = None
        origin: tuple[float, float, float] | None = None
        seen: set[str] = set()
        last_us = 0  # the latest IMU/ATT time: a GPS without a boot time (ArduPilot < 3.2) arrived then
        baro: float | None = None  # the barometer's latest height since the last IMU sample (on the next)
        scanner = DataFlashScanner(self.path, FIELDS, st)
        for name, v in scanner:
            if pending_gps is not None and name != "GPA":
                yield from self._gnss(pending_gps, None, delay_us)
                pending_gps = None
            if name == "IMU":
                t, gx, gy, gz, ax, ay, az = v
                if not all(math.isfinite(x) for x in (gx, gy, gz, ax, ay, az)):
                    rejected["imu_non_finite"] += 1
                    continue
                if not (max(abs(ax), abs(ay), abs(az)) <= LIMITS.max_specific_force_m_s2
                        and max(abs(gx), abs(gy), abs(gz)) <= LIMITS.max_rate_rad_s):
                    rejected["imu_out_of_range"] += 1  # beyond the MAVLink codec's full scale, as ULog
                    continue
                decoded["imu"] += 1
                last_us = int(t)
                yield ImuSample(last_us, _vec(ax, ay, az), _vec(gx, gy, gz), baro)
                baro = None
            elif name == "BARO":  # (a NaN is passed on: the tight filter counts it, uses nothing)
                decoded["baro"] += 1
                baro = float(v[1])
            elif name == "ATT":
                t, roll, pitch, yaw = v
                if not all(math.isfinite(x) for x in (roll, pitch, yaw)):
                    rejected["attitude_non_finite"] += 1
                    continue
                decoded["attitude"] += 1
                last_us = int(t)
                yield AttitudeSample(last_us, np.array(euler_to_quaternion(
                    math.radians(roll), math.radians(pitch), math.radians(yaw))))
            elif name == "GPS":
                if delay_us is None:
                    delay_us = self._delay_us(params, old=scanner.resolved["GPS"][0] != "TimeUS")
                if math.isnan(v[0]):
                    v[0] = last_us
                    decoded["gnss_stamped_on_arrival"] += 1
                pending_gps = v
            elif name == "GPA":
                if pending_gps is not None and pending_gps[0] == v[0]:
                    yield from self._gnss(pending_gps, v, delay_us)
                    pending_gps = None
            elif name == "PARM":
                key = v[0].rstrip(b"\0").decode("ascii", "replace") if isinstance(v[0], bytes) else str(v[0])
                params[key] = float(v[1])
            elif name == "ORGN":
                if v[0] == 0 and origin is None:
                    origin = (v[1], v[2], v[3])
            elif name == "SIM":
                ref = _reference(TRUTH, v, rejected, "SIM")
                if ref is not None:
                    seen.add(name)
                    yield ref
            elif name == "POS" or origin is not None:  # POS, XKF1, NKF1 (these about the EKF origin)
                if name == "POS":
                    ref = _reference(AUTOPILOT, v, rejected, INFO[name].source)
                else:
                    lat, lon, alt = pymap3d.ned2geodetic(v[1], v[2], v[3], *origin)  # type: ignore[misc]
                    ref = _reference(AUTOPILOT, [v[0], float(lat), float(lon), float(alt)], rejected,
                                     INFO[name].source)
                if ref is not None:
                    seen.add(name)
                    yield ref
        if pending_gps is not None:
            yield from self._gnss(pending_gps, None, delay_us)
        if "SIM" in seen:
            self.references[TRUTH] = INFO["SIM"]
        for source in ("POS", "XKF1", "NKF1"):  # in order of preference
            if source in seen:
                self.references[AUTOPILOT] = INFO[source]
                break

    def _delay_us(self, params: dict[str, float], old: bool) -> float:
        for key in DELAY_PARAMS:
            if params.get(key, 0.0) > 0:
                self.gps_delay_ms, self.gps_delay_source = params[key], f"log parameter {key}"
                return params[key] * 1000
        if old:
            self.gps_delay_ms = OLD_DEFAULT_GPS_DELAY_MS
            self.gps_delay_source = "default of ArduCopter <= 3.2 (EKF_POS_DELAY 220 ms; the log sets none)"
        else:
            self.gps_delay_ms = DEFAULT_GPS_DELAY_MS
            self.gps_delay_source = "default (the log sets no GPS delay)"
        return self.gps_delay_ms * 1000

    def _gnss(self, gps: list[Any], gpa: list[Any] | None, delay_us: float | None) -> Iterator[GnssFix]:
        fix = _fix(gps, gpa, delay_us or 0.0)
        if fix is None:
            self.stats.rejected["gnss_non_finite"] += 1
            return
        self.stats.decoded["gnss"] += 1
        if gpa is None:
            self.stats.decoded["gnss_without_gpa"] += 1
        yield fix


def _fix(gps: list[Any], gpa: list[Any] | None, delay_us: float) -> GnssFix | None:
    t_us, status, nsats, hdop, lat, lon, alt, spd, course_deg, vz = gps
    if not all(math.isfinite(x) for x in (lat, lon, alt)) or abs(lat) > 90 or abs(lon) > 180:
        return None
    h_acc = v_acc = vel_acc = math.nan
    t_rx_us = int(t_us)
    have_vv = True
    if gpa is not None:
        h_acc = gpa[1] if gpa[1] > 0 else math.nan
        v_acc = gpa[2] if gpa[2] > 0 else math.nan
        t_rx_us = int(gpa[3]) * 1000
        vel_acc = gpa[4] if gpa[4] > 0 else math.nan  # NaN > 0 is False: not logged
        have_vv = gpa[5] != 0  # VV: the receiver gives a vertical velocity (NaN: not logged)
    return GnssFix(int(t_rx_us - delay_us), float(lat), float(lon), float(alt), int(status), int(nsats),
                   h_acc_m=float(h_acc), v_acc_m=float(v_acc), hdop=float(hdop),
                   v_ned_m_s=_velocity(spd, course_deg, vz if have_vv else math.nan),
                   vel_acc_m_s=float(vel_acc))


def _velocity(speed_m_s: float, course_deg: float, v_down_m_s: float) -> np.ndarray | None:
    """NED velocity from ground speed, course over ground (degrees from north) and the vertical
    speed (down positive, as ArduPilot logs ``VZ``); None without speed and course."""
    if not (math.isfinite(speed_m_s) and math.isfinite(course_deg)):
        return None
    c = math.radians(course_deg)
    return np.array((speed_m_s * math.cos(c), speed_m_s * math.sin(c),
                     v_down_m_s if math.isfinite(v_down_m_s) else math.nan))


def _reference(kind: str, v: list[Any], rejected: Any, source: str) -> Reference | None:
    t, lat, lon, alt = v
    finite = all(math.isfinite(x) for x in (lat, lon, alt))
    if not finite or abs(lat) > 90 or abs(lon) > 180 or not (lat or lon):
        rejected[f"{kind}_out_of_range"] += 1
        return None
    return Reference(kind, int(t), float(lat), float(lon), float(alt), source)


def _vec(x: float, y: float, z: float) -> Any:
    return np.array((x, y, z), dtype=float)


def _skips(st: ReaderStats) -> str:
    if not st.skipped:
        return ""
    parts = ", ".join(f"{n} {reason}" for reason, n in sorted(st.skipped.items()))
    return f" (skipped {st.skipped_bytes} bytes: {parts})"


def is_dataflash(head: bytes) -> bool:
    """A DataFlash log starts with a FMT message (A3 95 80)."""
    return head[:3] == HEAD + bytes((FMT_TYPE,))
