"""PX4 ULog ``.ulg`` -> replay events, streamed in file order.

The definitions section (message formats, initial parameters) is read by the ``pyulog`` package
(``ULog(..., parse_header_only=True)``); the data section is then streamed here: each
subscription (``A``) is laid out by pyulog's own ``_MessageAddLogged`` (the flattened field
names and numpy dtype pyulog uses), data messages (``D``) of the wanted topics (instance 0) are
decoded in batches with numpy, and events are yielded in the order the logger wrote them (its
arrival order). Memory stays flat in the log's length.

Topics and fields, read by name (they change between PX4 releases; a missing one ends the replay
with a one-line error naming the topic and field). Times are PX4 boot microseconds.

- ``sensor_combined``: ``gyro_rad[0..2]`` (rad/s), ``accelerometer_m_s2[0..2]`` (m/s², specific
  force), body FRD, at ``timestamp`` -> ImuSample.
- ``vehicle_attitude``: ``q[0..3]`` (w, x, y, z; body FRD to NED) at ``timestamp_sample`` when
  logged (non-zero), else ``timestamp`` -> AttitudeSample.
- ``vehicle_gps_position``: ``latitude_deg``/``longitude_deg``/``altitude_msl_m`` (newer) or
  ``lat``/``lon`` (1e-7 deg)/``alt`` (mm MSL) (older), ``fix_type``, ``satellites_used``,
  ``eph``/``epv`` (m), ``hdop``; velocity ``vel_n_m_s``/``vel_e_m_s``/``vel_d_m_s`` where
  ``vel_ned_valid``, with ``s_variance_m_s`` (the speed accuracy, m/s) as its accuracy.
  Validity time = ``timestamp_sample`` when logged and non-zero, else ``timestamp`` −
  ``EKF2_GPS_DELAY`` (the log's parameter, ms: what EKF2 itself assumes).
- ``vehicle_air_data`` (optional): ``baro_alt_meter`` (m, the standard atmosphere's pressure altitude),
  carried by the next ``sensor_combined`` sample (``ImuSample.pressure_alt_m``: the tight filter's
  barometer; the loose filter has none).
- The autopilot's estimate: ``vehicle_global_position`` (``lat``, ``lon`` deg, ``alt`` m MSL) or,
  when the log has none, ``vehicle_local_position`` (``x``, ``y``, ``z`` about
  ``ref_lat``/``ref_lon``/``ref_alt``, rows with ``xy_global`` set); both geodetic.
- Truth (SITL): ``vehicle_global_position_groundtruth`` or ``vehicle_local_position_groundtruth``
  (same fields). PX4 SITL logs the truth's altitude as 0: then only its horizontal position
  is trusted and the vertical mean offset is removed (alignment ``vertical_mean_offset``).
"""

from __future__ import annotations

import contextlib
import io
import math
import struct
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np
import pymap3d

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

IMU_TOPIC = "sensor_combined"
ATTITUDE_TOPIC = "vehicle_attitude"
GNSS_TOPIC = "vehicle_gps_position"
AUTOPILOT_TOPICS = ("vehicle_global_position", "vehicle_local_position")
TRUTH_TOPICS = ("vehicle_global_position_groundtruth", "vehicle_local_position_groundtruth")
INPUT_TOPICS = (IMU_TOPIC, ATTITUDE_TOPIC, GNSS_TOPIC)
BARO_TOPIC = "vehicle_air_data"  # optional: the barometer's altitude on the next IMU sample
TOPICS = (*INPUT_TOPICS, *AUTOPILOT_TOPICS, *TRUTH_TOPICS, BARO_TOPIC)
LOCAL_FIELDS = (("x",), ("y",), ("z",), ("ref_lat",), ("ref_lon",), ("ref_alt",), ("xy_global",))
REQUIRED_FIELDS: dict[str, tuple[tuple[str, ...], ...]] = {
    IMU_TOPIC: (*((f"gyro_rad[{i}]",) for i in range(3)), *((f"accelerometer_m_s2[{i}]",) for i in range(3))),
    ATTITUDE_TOPIC: tuple((f"q[{i}]",) for i in range(4)),
    GNSS_TOPIC: (("latitude_deg", "lat"), ("longitude_deg", "lon"), ("altitude_msl_m", "alt"), ("fix_type",),
                 ("satellites_used", "satellites_visible"), ("eph",), ("epv",)),
    "vehicle_global_position": (("lat",), ("lon",), ("alt",)),
    "vehicle_global_position_groundtruth": (("lat",), ("lon",), ("alt",)),
    "vehicle_local_position": LOCAL_FIELDS,
    "vehicle_local_position_groundtruth": LOCAL_FIELDS,
    BARO_TOPIC: (("baro_alt_meter",),),
}
DEFAULT_EKF2_GPS_DELAY_MS = 110.0  # PX4's default, used when the log has no EKF2_GPS_DELAY
ULOG_MAGIC = b"ULog\x01\x12\x35"
BATCH = 2048  # data messages decoded together
MSG_DATA, MSG_ADD, MSG_SYNC = ord("D"), ord("A"), ord("S")
KNOWN_TYPES = frozenset(ord(c) for c in "FDIMPQARSOLCB")
SYNC_BYTES = b"\x2f\x73\x13\x20\x25\x0c\xbb\x12"


def is_ulog(head: bytes) -> bool:
    return head[:7] == ULOG_MAGIC


class _KeepOpen:
    """A file for pyulog's header parser that remembers where it stopped instead of closing."""

    def __init__(self, f: IO[bytes]) -> None:
        self.f, self.stopped_at = f, -1

    def read(self, n: int = -1) -> bytes:
        return self.f.read(n)

    def seek(self, offset: int, whence: int = 0) -> int:
        return self.f.seek(offset, whence)

    def tell(self) -> int:
        return self.f.tell()

    def close(self) -> None:
        self.stopped_at = self.f.tell()


class _Sub:
    """One wanted subscription: topic name and the numpy dtype of its data messages."""

    def __init__(self, name: str, dtype: np.dtype[Any]) -> None:
        self.name, self.dtype, self.size = name, dtype, dtype.itemsize
        self.payloads: list[bytes] = []


def _field(names: tuple[str, ...], arr: np.ndarray) -> np.ndarray:
    for n in names:
        if n in arr.dtype.names:  # type: ignore[operator]
            return arr[n]
    raise KeyError(names[0])


class ULogScanner:
    """Stream batches of ``(topic, structured rows)`` in file order: ``order`` lists, per data
    message, (topic, row) within the batch. Definitions are read once (``params``)."""

    def __init__(self, path: Path, wanted: tuple[str, ...], stats: ReaderStats) -> None:
        self.path, self.wanted, self.stats = path, frozenset(wanted), stats
        self.subscribed: set[str] = set()
        self.params: dict[str, float] = {}
        self.damaged: str | None = None  # what pyulog said of a damaged definitions section

    def no_topic(self, topic: str) -> UserError:
        """The one line for a topic the log does not define (naming a damaged definitions section)."""
        why = f" (its definitions section is damaged: pyulog: {self.damaged})" if self.damaged else ""
        return UserError(f"{self.path}: ULog has no topic {topic}{why}")

    def _definitions(self, f: IO[bytes]) -> Any:
        from pyulog import ULog

        handle = _KeepOpen(f)
        said = io.StringIO()  # pyulog prints what it finds damaged on stdout (which --json keeps clean)
        try:
            with contextlib.redirect_stdout(said):
                ulog = ULog(handle, parse_header_only=True)
        except Exception as exc:  # noqa: BLE001 - pyulog raises many kinds on a damaged file
            detail = str(exc).splitlines()[0] if str(exc) else "no detail"
            raise UserError(f"{self.path}: not a readable ULog ({type(exc).__name__}: {detail})") from None
        lines = [line.strip() for line in said.getvalue().splitlines() if line.strip()]
        if lines:
            self.damaged = lines[-1]
            self._skip("definitions_damaged", 0)
        self.params = {k: float(v) for k, v in ulog.initial_parameters.items() if isinstance(v, int | float)}
        f.seek(handle.stopped_at)
        return ulog

    def batches(self) -> Iterator[tuple[dict[str, np.ndarray], list[tuple[str, int]]]]:
        from pyulog import ULog

        st = self.stats
        st.size = self.path.stat().st_size
        with open(self.path, "rb") as f:
            ulog = self._definitions(f)
            formats = ulog.message_formats
            subs: dict[int, _Sub] = {}
            order: list[tuple[str, int]] = []
            counts: dict[str, int] = {}
            while True:
                head = f.read(3)
                if len(head) < 3:
                    if head:
                        self._skip("truncated", len(head))
                    break
                size, mtype = struct.unpack("<HB", head)
                if mtype not in KNOWN_TYPES:
                    if not self._resync(f, f.tell() - 3):
                        break
                    continue
                body = f.read(size)
                if len(body) < size:
                    self._skip("truncated", 3 + len(body))
                    break
                st.records += 1
                if mtype == MSG_DATA:
                    sub = subs.get(body[0] | body[1] << 8) if size >= 2 else None
                    if sub is None:
                        continue
                    if size - 2 < sub.size:
                        st.rejected[f"{sub.name}_short_message"] += 1
                        continue
                    k = counts.get(sub.name, 0)
                    counts[sub.name] = k + 1
                    sub.payloads.append(body[2 : 2 + sub.size])
                    order.append((sub.name, k))
                    if len(order) >= BATCH:
                        st.position = f.tell()
                        yield self._decode(subs), order
                        order, counts = [], {}
                elif mtype == MSG_ADD:
                    try:
                        added = ULog._MessageAddLogged(body, None, formats)  # noqa: SLF001 - pyulog's layout
                    except (KeyError, IndexError, ValueError, struct.error):
                        st.rejected["subscription_unknown_format"] += 1
                        continue
                    name = added.message_name
                    if name in self.wanted and added.multi_id == 0 and self._usable(name, added.dtype):
                        same = next((x for x in subs.values() if x.name == name), None)
                        if same is not None and same.dtype != added.dtype:
                            st.rejected[f"{name}_layout_changed"] += 1
                            continue
                        subs[added.msg_id] = same or _Sub(name, added.dtype)
                        self.subscribed.add(name)
        st.position = st.size
        if order:
            yield self._decode(subs), order

    def _usable(self, name: str, dtype: np.dtype[Any]) -> bool:
        """True if the topic has the fields this reader needs. A missing field of an estimator
        input is a UserError naming it; of a reference topic, counted (the topic is not used)."""
        names = dtype.names or ()
        for alternatives in REQUIRED_FIELDS.get(name, ()):
            if not any(a in names for a in alternatives):
                if name in INPUT_TOPICS:
                    missing = " or ".join(alternatives)
                    raise UserError(f"{self.path}: ULog topic {name} has no field {missing}")
                self.stats.rejected[f"{name}_unknown_layout"] += 1
                return False
        return True

    @staticmethod
    def _decode(subs: dict[int, _Sub]) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        for sub in subs.values():
            if sub.payloads:
                out[sub.name] = np.frombuffer(b"".join(sub.payloads), dtype=sub.dtype)
                sub.payloads = []
        return out

    def _skip(self, reason: str, size: int) -> None:
        self.stats.skipped[reason] += 1
        self.stats.skipped_bytes += size

    def _resync(self, f: IO[bytes], at: int) -> bool:
        """Skip to the next sync message after a corrupt header; False at the end of the file."""
        f.seek(at + 1)
        tail = b""
        while True:
            block = f.read(1 << 16)
            if not block:
                self._skip("garbage", f.tell() - at)
                return False
            data = tail + block
            i = data.find(SYNC_BYTES)
            if i >= 3:
                start = f.tell() - len(data) + i - 3  # the sync message's own header
                self._skip("garbage", start - at)
                f.seek(start)
                return True
            tail = data[-(len(SYNC_BYTES) + 3) :]


class ULogSource:
    format = "ulog"
    anchor = None  # home: the first 3-D fix

    def __init__(self, path: Path) -> None:
        self.path = path
        self.stats = ReaderStats()
        self.sources: dict[str, str | None] = {
            "imu": IMU_TOPIC, "attitude": ATTITUDE_TOPIC, "gnss": GNSS_TOPIC}
        self.references: dict[str, ReferenceInfo] = {}
        self.gps_delay_ms: float | None = None
        self.gps_delay_source = ""
        self._gps_rows = 0

    def first_fix(self) -> GnssFix | None:
        scanner = ULogScanner(self.path, (GNSS_TOPIC,), ReaderStats())
        decode = _GnssDecoder(scanner)
        for rows, _ in scanner.batches():
            arr = rows.get(GNSS_TOPIC)
            if arr is None:
                continue
            self._gps_rows += arr.size
            for fix in decode(arr):
                if isinstance(fix, GnssFix) and fix.fix_type >= MIN_FIX_TYPE_3D and math.isfinite(fix.alt_m):
                    return fix
        if GNSS_TOPIC not in scanner.subscribed:
            raise scanner.no_topic(GNSS_TOPIC)
        return None

    def describe_empty(self) -> str:
        return f"no usable {GNSS_TOPIC} 3-D fix (fix_type >= 3) in {self._gps_rows} messages"

    def __iter__(self) -> Iterator[Event]:
        scanner = ULogScanner(self.path, TOPICS, self.stats)
        gnss = _GnssDecoder(scanner)
        decoders: dict[str, Callable[[np.ndarray], list[Any]]] = {
            IMU_TOPIC: _imu, ATTITUDE_TOPIC: _attitude, GNSS_TOPIC: gnss}
        seen: dict[str, bool] = {}  # reference topic -> all its altitudes were 0 so far
        rejected, decoded = self.stats.rejected, self.stats.decoded
        group = {IMU_TOPIC: "imu", ATTITUDE_TOPIC: "attitude", GNSS_TOPIC: "gnss"}
        baro: float | None = None  # the barometer's latest altitude since the last IMU sample (on the next)
        for rows, order in scanner.batches():
            events: dict[str, list[Any]] = {}
            for name, arr in rows.items():
                if name == BARO_TOPIC:
                    events[name] = arr["baro_alt_meter"].astype(float).tolist()
                    continue
                if name in decoders:
                    events[name] = decoders[name](arr)
                    continue
                kind = AUTOPILOT if name in AUTOPILOT_TOPICS else TRUTH
                local = name.startswith("vehicle_local")
                events[name] = _references(kind, arr, local, name)
                alt = arr["ref_alt"] if local else arr["alt"]
                seen[name] = seen.get(name, True) and bool(np.all(alt == 0))
            for name, k in order:
                evs = events.get(name)
                if evs is None:
                    continue
                ev = evs[k]
                if name == BARO_TOPIC:  # (a NaN is passed on: the tight filter counts it, uses nothing)
                    baro = ev
                    decoded["baro"] += 1
                    continue
                if baro is not None and type(ev) is ImuSample:
                    ev = ImuSample(ev.t_us, ev.acc_frd_m_s2, ev.gyro_frd_rad_s, baro)
                    baro = None
                if isinstance(ev, str):
                    rejected[ev] += 1
                    continue
                if name in group:
                    decoded[group[name]] += 1
                yield ev
        for topic in INPUT_TOPICS:
            if topic not in scanner.subscribed:
                raise scanner.no_topic(topic)
        for kind, topics in ((AUTOPILOT, AUTOPILOT_TOPICS), (TRUTH, TRUTH_TOPICS)):
            found = [t for t in topics if t in seen]  # the global one first when logged
            if found:
                zero_alt = kind == TRUTH and seen[found[0]]
                alignment = "vertical_mean_offset" if zero_alt else "geodetic"
                self.references[kind] = _info(kind, found[0], alignment)
        self.gps_delay_ms, self.gps_delay_source = gnss.delay_ms, gnss.describe()


def _info(kind: str, topic: str, alignment: str) -> ReferenceInfo:
    what = {AUTOPILOT: "PX4's own estimate", TRUTH: "PX4 SITL ground truth"}[kind]
    note = f"estimated position vs {what} ({topic}, converted into the replay's frame)"
    if alignment != "geodetic":
        note += "; the truth's altitude is logged as 0: vertical mean offset removed"
    return ReferenceInfo(topic, alignment, note)


def _imu(arr: np.ndarray) -> list[Any]:
    t = arr["timestamp"].astype(np.int64)
    gyro = np.column_stack([arr[f"gyro_rad[{i}]"] for i in range(3)]).astype(float)
    acc = np.column_stack([arr[f"accelerometer_m_s2[{i}]"] for i in range(3)]).astype(float)
    finite = np.isfinite(gyro).all(axis=1) & np.isfinite(acc).all(axis=1)
    # beyond the MAVLink codec's full scale (a damaged 1e36 m/s² broke the filter's covariance): counted
    within = (np.abs(acc) <= LIMITS.max_specific_force_m_s2).all(axis=1) & (
        np.abs(gyro) <= LIMITS.max_rate_rad_s).all(axis=1)
    return [ImuSample(int(t[i]), acc[i], gyro[i]) if finite[i] and within[i]
            else "imu_out_of_range" if finite[i] else "imu_non_finite" for i in range(t.size)]


def _sample_time_us(arr: np.ndarray) -> np.ndarray:
    """``timestamp_sample`` where logged and non-zero, else ``timestamp``."""
    t = arr["timestamp"].astype(np.int64)
    if "timestamp_sample" in (arr.dtype.names or ()):
        ts = arr["timestamp_sample"].astype(np.int64)
        t = np.where(ts > 0, ts, t)
    return t


def _attitude(arr: np.ndarray) -> list[Any]:
    t = _sample_time_us(arr)
    q = np.column_stack([arr[f"q[{i}]"] for i in range(4)]).astype(float)
    norm = np.linalg.norm(q, axis=1)
    ok = np.isfinite(norm) & (np.abs(norm - 1.0) < 0.1)
    return [AttitudeSample(int(t[i]), q[i] / norm[i]) if ok[i] else "attitude_not_unit"
            for i in range(t.size)]


class _GnssDecoder:
    """vehicle_gps_position rows -> GnssFix (validity time per row, see the module doc)."""

    def __init__(self, scanner: ULogScanner) -> None:
        self.scanner = scanner
        self.with_sample_time = self.with_delay = 0

    @property
    def delay_ms(self) -> float:
        return self.scanner.params.get("EKF2_GPS_DELAY", DEFAULT_EKF2_GPS_DELAY_MS)

    def describe(self) -> str:
        parts = []
        if self.with_sample_time:
            parts.append(f"timestamp_sample for {self.with_sample_time} fixes")
        if self.with_delay:
            where = "log parameter" if "EKF2_GPS_DELAY" in self.scanner.params else "default"
            parts.append(f"timestamp minus the {where} EKF2_GPS_DELAY for {self.with_delay} fixes "
                         "(timestamp_sample not logged)")
        return "; ".join(parts)

    def __call__(self, arr: np.ndarray) -> list[Any]:
        names = arr.dtype.names or ()
        newer = "latitude_deg" in names  # newer PX4: degrees and metres; older: 1e-7 deg and mm
        lat = _field(("latitude_deg", "lat"), arr).astype(float) * (1.0 if newer else 1e-7)
        lon = _field(("longitude_deg", "lon"), arr).astype(float) * (1.0 if newer else 1e-7)
        alt = _field(("altitude_msl_m", "alt"), arr).astype(float) * (1.0 if newer else 1e-3)
        t = arr["timestamp"].astype(np.int64)
        ts = arr["timestamp_sample"].astype(np.int64) if "timestamp_sample" in names else np.zeros_like(t)
        delay_us = int(round(self.delay_ms * 1000))
        t_valid = np.where(ts > 0, ts, t - delay_us)
        self.with_sample_time += int(np.count_nonzero(ts > 0))
        self.with_delay += int(np.count_nonzero(ts <= 0))
        fix = _field(("fix_type",), arr).astype(int)
        sats = _field(("satellites_used", "satellites_visible"), arr).astype(int)
        eph, epv = arr["eph"].astype(float), arr["epv"].astype(float)
        hdop = arr["hdop"].astype(float) if "hdop" in names else np.full(t.size, math.nan)
        ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
        vel, vel_ok, vel_acc = _velocity(arr)
        return [GnssFix(int(t_valid[i]), float(lat[i]), float(lon[i]), float(alt[i]), int(fix[i]),
                        int(sats[i]), h_acc_m=float(eph[i]), v_acc_m=float(epv[i]), hdop=float(hdop[i]),
                        v_ned_m_s=vel[i].copy() if vel_ok[i] else None, vel_acc_m_s=float(vel_acc[i]))
                if ok[i] else "gnss_non_finite" for i in range(t.size)]


def _velocity(arr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """vehicle_gps_position's NED velocity (n, 3), where it is valid (``vel_ned_valid``, and the
    fields logged), and its speed accuracy (``s_variance_m_s``, a 1-σ speed in m/s despite its
    name: EKF2 reads it as the speed accuracy; NaN when not logged or not > 0)."""
    names = arr.dtype.names or ()
    n = arr.shape[0]
    fields = ("vel_n_m_s", "vel_e_m_s", "vel_d_m_s")
    if not all(f in names for f in fields):
        return np.full((n, 3), math.nan), np.zeros(n, dtype=bool), np.full(n, math.nan)
    vel = np.column_stack([arr[f].astype(float) for f in fields])
    valid = arr["vel_ned_valid"].astype(bool) if "vel_ned_valid" in names else np.ones(n, dtype=bool)
    valid &= np.isfinite(vel).all(axis=1)
    acc = arr["s_variance_m_s"].astype(float) if "s_variance_m_s" in names else np.full(n, math.nan)
    return vel, valid, np.where(acc > 0, acc, math.nan)


def _references(kind: str, arr: np.ndarray, local: bool, source: str) -> list[Any]:
    t = _sample_time_us(arr)
    if local:
        lat, lon, alt = pymap3d.ned2geodetic(arr["x"].astype(float), arr["y"].astype(float),
                                             arr["z"].astype(float), arr["ref_lat"].astype(float),
                                             arr["ref_lon"].astype(float), arr["ref_alt"].astype(float))
        ok = arr["xy_global"].astype(bool)
    else:
        lat, lon, alt = arr["lat"].astype(float), arr["lon"].astype(float), arr["alt"].astype(float)
        ok = np.ones(t.size, dtype=bool)
    lat, lon, alt = np.atleast_1d(lat), np.atleast_1d(lon), np.atleast_1d(alt)
    ok &= np.isfinite(lat) & np.isfinite(lon) & np.isfinite(alt) & ((lat != 0) | (lon != 0))
    return [Reference(kind, int(t[i]), float(lat[i]), float(lon[i]), float(alt[i]), source) if ok[i]
            else f"{kind}_not_global" for i in range(t.size)]
