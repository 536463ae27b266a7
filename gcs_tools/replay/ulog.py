"""PX4 ULog ``.ulg`` -> replay events (read with the ``pyulog`` package).

Topics and fields, read by name (they change between PX4 releases; a missing one ends the replay
with a one-line error naming the topic and field). Times are PX4 boot microseconds.

- ``sensor_combined``: ``gyro_rad[0..2]`` (rad/s), ``accelerometer_m_s2[0..2]`` (m/s², specific
  force), body FRD, at ``timestamp`` -> ImuSample.
- ``vehicle_attitude``: ``q[0..3]`` (w, x, y, z; body FRD to NED) at ``timestamp_sample`` when
  logged (non-zero), else ``timestamp`` -> AttitudeSample.
- ``vehicle_gps_position``: ``latitude_deg``/``longitude_deg``/``altitude_msl_m`` (newer) or
  ``lat``/``lon`` (1e-7 deg)/``alt`` (mm MSL) (older), ``fix_type``, ``satellites_used``,
  ``eph``/``epv`` (m), ``hdop``. Validity time = ``timestamp_sample`` when logged and non-zero,
  else ``timestamp`` − ``EKF2_GPS_DELAY`` (the log's parameter, ms: what EKF2 itself assumes).
- The autopilot's estimate: ``vehicle_global_position`` (``lat``, ``lon`` deg, ``alt`` m MSL) or,
  without it, ``vehicle_local_position`` (``x``, ``y``, ``z`` about ``ref_lat``/``ref_lon``/
  ``ref_alt``, rows with ``xy_global`` set); both geodetic.
- Truth (SITL): ``vehicle_global_position_groundtruth`` or ``vehicle_local_position_groundtruth``
  (same fields). PX4 SITL logs the truth's altitude as 0: then only its horizontal position
  is trusted and the vertical mean offset is removed (alignment ``vertical_mean_offset``).

Events are ordered by ``timestamp`` (the time PX4 published each message: its arrival). pyulog
loads the selected topics whole, so memory grows with the log (the tlog and DataFlash readers
stream).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d

from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
from companion.errors import UserError
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
TOPICS = (IMU_TOPIC, ATTITUDE_TOPIC, GNSS_TOPIC, *AUTOPILOT_TOPICS, *TRUTH_TOPICS)
DEFAULT_EKF2_GPS_DELAY_MS = 110.0  # PX4's default, used when the log has no EKF2_GPS_DELAY
ULOG_MAGIC = b"ULog\x01\x12\x35"


def is_ulog(head: bytes) -> bool:
    return head[:7] == ULOG_MAGIC


class _Topic:
    def __init__(self, path: Path, name: str, data: dict[str, np.ndarray]) -> None:
        self.path, self.name, self.data = path, name, data

    def field(self, *names: str) -> np.ndarray:
        """The first of ``names`` present (alternatives across PX4 releases)."""
        for n in names:
            if n in self.data:
                return self.data[n]
        raise UserError(f"{self.path}: ULog topic {self.name} has no field {' or '.join(names)}")

    def has(self, name: str) -> bool:
        return name in self.data

    def sample_time_us(self) -> np.ndarray:
        """``timestamp_sample`` where logged and non-zero, else ``timestamp``."""
        t = self.data["timestamp"].astype(np.int64)
        if "timestamp_sample" in self.data:
            ts = self.data["timestamp_sample"].astype(np.int64)
            t = np.where(ts > 0, ts, t)
        return t


class ULogSource:
    format = "ulog"

    def __init__(self, path: Path) -> None:
        self.path = path
        self.stats = ReaderStats()
        self.sources: dict[str, str | None] = {
            "imu": IMU_TOPIC, "attitude": ATTITUDE_TOPIC, "gnss": GNSS_TOPIC}
        self.references: dict[str, ReferenceInfo] = {}
        self.gps_delay_ms: float | None = None
        self.gps_delay_source = ""
        self._topics: dict[str, _Topic] | None = None
        self._params: dict[str, float] = {}

    def _load(self) -> dict[str, _Topic]:
        if self._topics is None:
            from pyulog import ULog

            try:
                ulog = ULog(str(self.path), list(TOPICS))
            except Exception as exc:  # noqa: BLE001 - pyulog raises many kinds on a damaged file
                raise UserError(f"{self.path}: not a readable ULog ({type(exc).__name__}: "
                                f"{str(exc).splitlines()[0] if str(exc) else 'no detail'})") from None
            topics: dict[str, _Topic] = {}
            for d in ulog.data_list:
                if d.multi_id == 0 and d.name not in topics:
                    topics[d.name] = _Topic(self.path, d.name, d.data)
            self._topics = topics
            self._params = {k: float(v) for k, v in ulog.initial_parameters.items()
                            if isinstance(v, int | float)}
            self.stats.size = self.stats.position = self.path.stat().st_size
            self.stats.records = sum(len(t.data["timestamp"]) for t in topics.values())
            if ulog.file_corruption:
                self.stats.skipped["file_corruption"] += 1
        return self._topics

    def _topic(self, name: str) -> _Topic:
        topics = self._load()
        if name not in topics:
            raise UserError(f"{self.path}: ULog has no topic {name} (logged: "
                            f"{', '.join(sorted(topics)) or 'none of ' + ', '.join(TOPICS)})")
        return topics[name]

    def _fixes(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Arrival times and the GnssFix columns of every logged fix."""
        g = self._topic(GNSS_TOPIC)
        newer = g.has("latitude_deg")  # newer PX4: degrees and metres; older: 1e-7 deg and mm
        lat = g.field("latitude_deg", "lat").astype(float) * (1.0 if newer else 1e-7)
        lon = g.field("longitude_deg", "lon").astype(float) * (1.0 if newer else 1e-7)
        alt = g.field("altitude_msl_m", "alt").astype(float) * (1.0 if newer else 1e-3)
        t_arrival = g.data["timestamp"].astype(np.int64)
        ts = g.data.get("timestamp_sample")
        delay_ms = self._params.get("EKF2_GPS_DELAY", DEFAULT_EKF2_GPS_DELAY_MS)
        if ts is not None and np.all(ts > 0):
            t_valid = ts.astype(np.int64)
            self.gps_delay_ms, self.gps_delay_source = None, "timestamp_sample"
        else:
            t_valid = t_arrival - int(round(delay_ms * 1000))
            self.gps_delay_ms = delay_ms
            self.gps_delay_source = ("log parameter EKF2_GPS_DELAY" if "EKF2_GPS_DELAY" in self._params
                                     else "default EKF2_GPS_DELAY") + " (timestamp_sample not logged)"
        cols = {"t": t_valid, "lat": lat, "lon": lon, "alt": alt, "fix": g.field("fix_type").astype(int),
                "sats": g.field("satellites_used", "satellites_visible").astype(int),
                "eph": g.field("eph").astype(float), "epv": g.field("epv").astype(float),
                "hdop": g.field("hdop").astype(float) if g.has("hdop") else np.full(lat.shape, math.nan)}
        return t_arrival, cols

    def first_fix(self) -> GnssFix | None:
        _, c = self._fixes()
        good = np.flatnonzero((c["fix"] >= MIN_FIX_TYPE_3D) & np.isfinite(c["lat"]) & np.isfinite(c["alt"]))
        return None if good.size == 0 else _fix(c, int(good[0]))

    def describe_empty(self) -> str:
        t, _ = self._fixes()
        return f"no usable {GNSS_TOPIC} 3-D fix (fix_type >= 3) in {t.size} messages"

    def _references(
        self, kind: str, topics: tuple[str, str]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(arrival t, validity t, (n, 3) lat/lon/alt) of the first topic present, or None."""
        loaded = self._load()
        glob, local = topics
        alignment = "geodetic"
        if glob in loaded:
            tp = loaded[glob]
            lla = np.column_stack((tp.field("lat"), tp.field("lon"), tp.field("alt"))).astype(float)
            name = glob
        elif local in loaded:
            tp = loaded[local]
            ok = tp.field("xy_global").astype(bool) & np.isfinite(tp.field("ref_lat"))
            lat, lon, alt = pymap3d.ned2geodetic(tp.field("x")[ok], tp.field("y")[ok], tp.field("z")[ok],
                                                 tp.field("ref_lat")[ok], tp.field("ref_lon")[ok],
                                                 tp.field("ref_alt")[ok])
            lla = np.full((ok.size, 3), math.nan)
            lla[ok] = np.column_stack((lat, lon, alt))
            name = local
        else:
            return None
        if kind == TRUTH and lla.size and np.all(lla[:, 2] == 0):
            alignment = "vertical_mean_offset"
        what = {AUTOPILOT: "PX4's own estimate", TRUTH: "PX4 SITL ground truth"}[kind]
        note = f"estimated position vs {what} ({name}, converted into the replay's frame)"
        if alignment != "geodetic":
            note += "; the truth's altitude is logged as 0: vertical mean offset removed"
        self.references[kind] = ReferenceInfo(name, alignment, note)
        return tp.data["timestamp"].astype(np.int64), tp.sample_time_us(), lla

    def __iter__(self) -> Iterator[Event]:
        imu = self._topic(IMU_TOPIC)
        att = self._topic(ATTITUDE_TOPIC)
        gyro = np.column_stack([imu.field(f"gyro_rad[{i}]") for i in range(3)]).astype(float)
        acc = np.column_stack([imu.field(f"accelerometer_m_s2[{i}]") for i in range(3)]).astype(float)
        t_imu = imu.data["timestamp"].astype(np.int64)
        q = np.column_stack([att.field(f"q[{i}]") for i in range(4)]).astype(float)
        t_att_arrival, t_att = att.data["timestamp"].astype(np.int64), att.sample_time_us()
        t_gps_arrival, fixes = self._fixes()
        streams: list[tuple[np.ndarray, int]] = [(t_imu, 0), (t_att_arrival, 1), (t_gps_arrival, 2)]
        refs: list[tuple[str, np.ndarray, np.ndarray]] = []
        for kind, topics in ((AUTOPILOT, AUTOPILOT_TOPICS), (TRUTH, TRUTH_TOPICS)):
            found = self._references(kind, topics)
            if found is not None:
                streams.append((found[0], 3 + len(refs)))
                refs.append((kind, found[1], found[2]))
        arrival = np.concatenate([t for t, _ in streams])
        which = np.concatenate([np.full(t.size, k, dtype=np.int8) for t, k in streams])
        row = np.concatenate([np.arange(t.size) for t, _ in streams])
        order = np.argsort(arrival, kind="stable")
        st = self.stats
        decoded, rejected = st.decoded, st.rejected
        for k, i in zip(which[order].tolist(), row[order].tolist(), strict=True):
            if k == 0:
                a, w = acc[i], gyro[i]
                if not (np.isfinite(a).all() and np.isfinite(w).all()):
                    rejected["imu_non_finite"] += 1
                    continue
                decoded["imu"] += 1
                yield ImuSample(int(t_imu[i]), a, w)
            elif k == 1:
                qi = q[i]
                norm = float(np.linalg.norm(qi))
                if not (math.isfinite(norm) and abs(norm - 1.0) < 0.1):
                    rejected["attitude_not_unit"] += 1
                    continue
                decoded["attitude"] += 1
                yield AttitudeSample(int(t_att[i]), qi / norm)
            elif k == 2:
                if not (math.isfinite(fixes["lat"][i]) and math.isfinite(fixes["lon"][i])):
                    rejected["gnss_non_finite"] += 1
                    continue
                decoded["gnss"] += 1
                yield _fix(fixes, i)
            else:
                kind, t_ref, lla = refs[k - 3]
                lat, lon, alt = lla[i]
                if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(alt)) or not (lat or lon):
                    rejected[f"{kind}_not_global"] += 1
                    continue
                yield Reference(kind, int(t_ref[i]), float(lat), float(lon), float(alt))


def _fix(c: dict[str, Any], i: int) -> GnssFix:
    return GnssFix(int(c["t"][i]), float(c["lat"][i]), float(c["lon"][i]), float(c["alt"][i]),
                   int(c["fix"][i]), int(c["sats"][i]), h_acc_m=float(c["eph"][i]),
                   v_acc_m=float(c["epv"][i]), hdop=float(c["hdop"][i]))
