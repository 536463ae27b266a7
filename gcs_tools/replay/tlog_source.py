"""MAVLink tlog -> replay events (the fast, streaming reader of :mod:`companion.mavlink.tlog`).

One IMU source (the first of HIGHRES_IMU, RAW_IMU, SCALED_IMU to appear) and one attitude
source (ATTITUDE_QUATERNION or ATTITUDE) are used; messages of the other source of the same kind
are counted (``imu_other_source_ignored``), not fed twice. GPS_RAW_INT ``time_usec`` is the fix's
validity time. References: SIM_STATE (truth, at the last IMU time: it has no stamp), the
autopilot's GLOBAL_POSITION_INT (geodetic) or, when the log has none, LOCAL_POSITION_NED (about
an origin the log does not state: aligned by mean offset). Both are yielded; ``references``
names the one reported.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from companion.domain.samples import GnssFix, ImuSample
from companion.mavlink import codec as mc
from companion.mavlink.tlog import TlogReader, read_tlog
from gcs_tools.replay.events import (
    AUTOPILOT,
    MIN_FIX_TYPE_3D,
    TRUTH,
    Event,
    LocalReference,
    ReaderStats,
    Reference,
    ReferenceInfo,
)

IMU_TYPES = ("HIGHRES_IMU", "RAW_IMU", "SCALED_IMU")
ATTITUDE_TYPES = ("ATTITUDE_QUATERNION", "ATTITUDE")
GNSS_TYPE = "GPS_RAW_INT"
REFERENCE_TYPES = ("SIM_STATE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED")
INFO = {
    "SIM_STATE": ReferenceInfo("SIM_STATE", "geodetic", "estimated position vs SIM_STATE truth"),
    "GLOBAL_POSITION_INT": ReferenceInfo(
        "GLOBAL_POSITION_INT", "geodetic",
        "estimated position vs the autopilot's GLOBAL_POSITION_INT (lat, lon, alt MSL) converted into "
        "the replay's frame"),
    "LOCAL_POSITION_NED": ReferenceInfo(
        "LOCAL_POSITION_NED", "mean_offset",
        "estimated position vs the autopilot's LOCAL_POSITION_NED (about the autopilot's own origin, "
        "not in the log: the mean offset is removed)"),
}


class TlogSource:
    format = "tlog"
    anchor = None  # home: the first 3-D fix

    def __init__(self, path: Path) -> None:
        self.path = path
        self.stats = ReaderStats()
        self.sources: dict[str, str | None] = {"imu": None, "attitude": None, "gnss": GNSS_TYPE}
        self.references: dict[str, ReferenceInfo] = {}
        self._reader: TlogReader | None = None

    def first_fix(self) -> GnssFix | None:
        for _, view in read_tlog(self.path, [GNSS_TYPE]):
            try:
                fix = mc.decode_gnss(view)
            except mc.CodecError:
                continue
            if fix.fix_type >= MIN_FIX_TYPE_3D and math.isfinite(fix.alt_m):
                return fix
        return None

    def describe_empty(self) -> str:
        probe = read_tlog(self.path)
        frames = sum(1 for _ in probe)
        what = "no usable GPS_RAW_INT 3-D fix" if frames else "no readable MAVLink frames"
        return f"{what} in {frames} frames{_describe_skips(probe)}"

    def __iter__(self) -> Iterator[Event]:
        reader = read_tlog(self.path, (*IMU_TYPES, *ATTITUDE_TYPES, GNSS_TYPE, *REFERENCE_TYPES))
        st, sources = self.stats, self.sources
        decoded, rejected = st.decoded, st.rejected
        decode_sample = mc.decode_sample
        last_imu_us = 0
        seen: set[str] = set()
        count = 0
        for _, view in reader:
            count += 1
            if count & 255 == 0:
                st.position, st.size = reader.position, reader.size
            kind = view.get_type()
            if kind in REFERENCE_TYPES:
                try:
                    ref = self._reference(view, kind, last_imu_us)
                except mc.CodecError as exc:
                    rejected[f"{kind.lower()}_{exc.reason}"] += 1
                    continue
                seen.add(kind)
                yield ref
                continue
            group = "imu" if kind in IMU_TYPES else "attitude" if kind in ATTITUDE_TYPES else "gnss"
            if group != "gnss":
                if sources[group] is None:
                    sources[group] = kind
                elif sources[group] != kind:
                    decoded[f"{group}_other_source_ignored"] += 1
                    continue
            try:
                sample = decode_sample(view)
            except mc.CodecError as exc:
                rejected[f"{group}_{exc.reason}"] += 1
                continue
            decoded[group] += 1
            if type(sample) is ImuSample:
                last_imu_us = sample.t_us
            yield sample  # type: ignore[misc]
        st.records, st.position, st.size = reader.frames, reader.size, reader.size
        st.skipped, st.skipped_bytes = reader.skipped, reader.skipped_bytes
        if "SIM_STATE" in seen:
            self.references[TRUTH] = INFO["SIM_STATE"]
        for source in ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"):  # in order of preference
            if source in seen:
                self.references[AUTOPILOT] = INFO[source]
                break

    @staticmethod
    def _reference(view: Any, kind: str, last_imu_us: int) -> Reference | LocalReference:
        if kind == "SIM_STATE":
            if view.lat_int or view.lon_int:
                lat, lon = view.lat_int / mc.DEG_E7, view.lon_int / mc.DEG_E7
            else:
                lat, lon = float(view.lat), float(view.lon)
            alt = float(view.alt)
            if not all(math.isfinite(v) for v in (lat, lon, alt)):
                raise mc.CodecError("non_finite", "SIM_STATE")
            if abs(lat) > 90 or abs(lon) > 180:
                raise mc.CodecError("out_of_range", "SIM_STATE lat/lon")
            return Reference(TRUTH, last_imu_us, lat, lon, alt, kind)
        if kind == "GLOBAL_POSITION_INT":
            lat, lon, alt = view.lat / mc.DEG_E7, view.lon / mc.DEG_E7, view.alt / 1000.0
            if not (lat or lon) or abs(lat) > 90 or abs(lon) > 180:
                raise mc.CodecError("out_of_range", "GLOBAL_POSITION_INT lat/lon")
            return Reference(AUTOPILOT, view.time_boot_ms * 1000, lat, lon, alt, kind)
        p = (float(view.x), float(view.y), float(view.z))
        if not all(math.isfinite(v) for v in p):
            raise mc.CodecError("non_finite", "LOCAL_POSITION_NED")
        return LocalReference(AUTOPILOT, view.time_boot_ms * 1000, p, kind)


def _describe_skips(reader: TlogReader) -> str:
    if not reader.skipped:
        return ""
    parts = ", ".join(f"{n} {reason}" for reason, n in sorted(reader.skipped.items()))
    return f" (skipped {reader.skipped_bytes} bytes: {parts})"
