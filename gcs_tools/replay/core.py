"""Replay a tlog through the estimator: samples in arrival order, estimates and a summary out.

The log is read with the fast reader of :mod:`companion.mavlink.tlog`; every message is turned
into a domain sample by :mod:`companion.mavlink.codec` and pushed to a
:class:`companion.estimator.Navigator` in the order it arrived. One IMU source (the first of
HIGHRES_IMU, RAW_IMU, SCALED_IMU to appear) and one attitude source (ATTITUDE_QUATERNION or
ATTITUDE) are used; messages of the other source of the same kind are counted, not fed twice.
References present in the log (SIM_STATE truth, the autopilot's GLOBAL_POSITION_INT /
LOCAL_POSITION_NED) and the GNSS fixes themselves give error statistics, named by reference.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix, ImuSample, NavEstimate
from companion.errors import UserError
from companion.mavlink import codec as mc
from companion.mavlink.tlog import TlogReader, read_tlog
from gcs_tools.evaluate.stats import summarize

if TYPE_CHECKING:
    from companion.estimator import EstimatorConfig

IMU_TYPES = ("HIGHRES_IMU", "RAW_IMU", "SCALED_IMU")
ATTITUDE_TYPES = ("ATTITUDE_QUATERNION", "ATTITUDE")
GNSS_TYPE = "GPS_RAW_INT"
REFERENCE_TYPES = ("SIM_STATE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED")
MIN_FIX_TYPE_3D = 3
# Decoded samples fed to the navigator at a time: one timer pair per chunk instead of per sample
# (the order, and so every estimate and counter, is unchanged).
FEED_CHUNK = 512
CSV_COLUMNS = (
    "t_s", "p_n_m", "p_e_m", "p_d_m", "v_n_m_s", "v_e_m_s", "v_d_m_s", "b_n_m", "b_e_m", "b_d_m",
    "beta", "nis",
    "var_p_n_m2", "var_p_e_m2", "var_p_d_m2", "var_v_n_m2_s2", "var_v_e_m2_s2", "var_v_d_m2_s2",
    "var_b_n_m2", "var_b_e_m2", "var_b_d_m2",
)


class NavigatorLike(Protocol):
    def push(self, sample: Any) -> None: ...
    def estimate(self) -> NavEstimate | None: ...
    def counters(self) -> dict[str, int]: ...


NavigatorFactory = Callable[[str, LocalNedFrame], NavigatorLike]
ImuHook = Callable[[int, NavigatorLike], None]


def default_navigator(
    method: str, frame: LocalNedFrame, config: EstimatorConfig | None = None
) -> NavigatorLike:
    """The real Navigator; ``config`` None = ``EstimatorConfig`` defaults (the real-log values)."""
    from companion.estimator import METHODS, EstimatorConfig, Navigator

    if method not in METHODS:
        raise UserError(f"unknown method {method!r} (choose from {', '.join(METHODS)})")
    return Navigator(config or EstimatorConfig(), method=method, frame=frame)


@dataclass
class _Series:
    """Estimates collected during the replay (kept as objects, turned into arrays at the end)."""

    estimates: list[NavEstimate] = field(default_factory=list)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        est = self.estimates
        t_us = np.array([e.t_us for e in est], dtype=np.int64)
        if not est:
            return t_us, np.zeros((0, len(CSV_COLUMNS) - 1))
        rows = np.column_stack((
            np.array([e.p_ned_m for e in est]), np.array([e.v_ned_m_s for e in est]),
            np.array([e.b_ned_m for e in est]), np.array([(e.beta, e.nis) for e in est]),
            np.array([e.cov_diag for e in est]),
        ))
        return t_us, rows.astype(float)


class _Feed:
    """Pushes decoded samples to the navigator in arrival order and takes the estimate rows."""

    def __init__(self, nav: NavigatorLike, period_us: int, series: _Series, on_imu: ImuHook | None) -> None:
        self.nav, self.period_us, self.series, self.on_imu = nav, period_us, series, on_imu
        self.next_row_us = -1
        self.estimator_s = 0.0

    def __call__(self, samples: list[Any]) -> None:
        push, estimate, rows = self.nav.push, self.nav.estimate, self.series.estimates
        next_row_us, period_us, on_imu = self.next_row_us, self.period_us, self.on_imu
        hook_s = 0.0
        t0 = time.perf_counter()
        for sample in samples:
            push(sample)
            if type(sample) is ImuSample:
                if sample.t_us >= next_row_us:
                    est = estimate()
                    if est is not None:
                        next_row_us = sample.t_us + period_us
                        rows.append(est)
                if on_imu is not None:  # telemetry / pacing: not the estimator's time
                    h0 = time.perf_counter()
                    on_imu(sample.t_us, self.nav)
                    hook_s += time.perf_counter() - h0
        self.estimator_s += time.perf_counter() - t0 - hook_s
        self.next_row_us = next_row_us
        samples.clear()


@dataclass
class ReplayResult:
    summary: dict[str, Any]
    t_us: np.ndarray  # (N,) estimate times
    table: np.ndarray  # (N, len(CSV_COLUMNS) - 1): the CSV columns after t_s


def parse_home(text: str) -> LocalNedFrame:
    """``"lat,lon,alt"`` (degrees, degrees, metres) -> frame; UserError on anything else."""
    try:
        lat, lon, alt = (float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--home {text!r}: expected lat,lon,alt (degrees, degrees, metres)") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and math.isfinite(alt)):
        raise UserError(f"--home {text!r}: latitude/longitude out of range")
    return LocalNedFrame(lat, lon, alt)


def first_good_fix(path: Path) -> GnssFix | None:
    """The first decodable 3-D fix of the log (reads only until it is found)."""
    for _, view in read_tlog(path, [GNSS_TYPE]):
        try:
            fix = mc.decode_gnss(view)
        except mc.CodecError:
            continue
        if fix.fix_type >= MIN_FIX_TYPE_3D and math.isfinite(fix.alt_m):
            return fix
    return None


def _describe_skips(reader: TlogReader) -> str:
    if not reader.skipped:
        return ""
    parts = ", ".join(f"{n} {reason}" for reason, n in sorted(reader.skipped.items()))
    return f" (skipped {reader.skipped_bytes} bytes: {parts})"


def _error_stats(
    t_ref_us: np.ndarray, p_ref: np.ndarray, t_est_us: np.ndarray, p_est: np.ndarray, note: str
) -> dict[str, Any]:
    """Horizontal and 3-D error of the estimate, interpolated to the reference times."""
    inside = (t_ref_us >= t_est_us[0]) & (t_ref_us <= t_est_us[-1]) if t_est_us.size else t_ref_us < 0
    t, ref = t_ref_us[inside], p_ref[inside]
    est = np.column_stack([np.interp(t, t_est_us, p_est[:, k]) for k in range(3)]).reshape(-1, 3)
    err = est - ref
    e3, eh = np.linalg.norm(err, axis=1), np.linalg.norm(err[:, :2], axis=1)
    out: dict[str, Any] = {"note": note, "n": int(t.size)}
    for name, e in (("error_3d_m", e3), ("error_horizontal_m", eh)):
        stats = summarize(e)
        stats["rmse"] = float(np.sqrt(np.mean(e**2))) if e.size else math.nan
        stats["max"] = float(e.max()) if e.size else math.nan
        out[name] = stats
    return out


def _distribution(x: np.ndarray) -> dict[str, float]:
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"n": 0}
    p5, p50 = np.percentile(x, [5.0, 50.0])
    return {"n": int(x.size), "mean": float(x.mean()), "min": float(x.min()), "p5": float(p5),
            "median": float(p50), "max": float(x.max()), "final": float(x[-1])}


class _References:
    """Reference positions found in the log, in the replay's local frame."""

    def __init__(self, frame: LocalNedFrame) -> None:
        self.frame = frame
        self.series: dict[str, tuple[list[int], list[np.ndarray]]] = {}

    def add(self, name: str, t_us: int, p_ned_m: np.ndarray) -> None:
        t, p = self.series.setdefault(name, ([], []))
        t.append(t_us)
        p.append(p_ned_m)

    def take(self, view: Any, last_imu_us: int, rejected: Counter[str]) -> None:
        kind = view.get_type()
        try:
            if kind == "SIM_STATE":
                truth = mc.decode_truth(view, self.frame, last_imu_us)
                self.add("sim_state_truth", truth.t_us, truth.p_ned_m)
            elif kind == "GLOBAL_POSITION_INT":
                lat, lon, alt = view.lat / mc.DEG_E7, view.lon / mc.DEG_E7, view.alt / 1000.0
                if not (lat or lon) or abs(lat) > 90 or abs(lon) > 180:
                    raise mc.CodecError("out_of_range", "GLOBAL_POSITION_INT lat/lon")
                self.add("autopilot_global_position", view.time_boot_ms * 1000,
                         self.frame.to_ned_m(lat, lon, alt))
            else:  # LOCAL_POSITION_NED: the autopilot's own origin, compared as-is
                p = np.array((view.x, view.y, view.z), dtype=float)
                if not np.isfinite(p).all():
                    raise mc.CodecError("non_finite", "LOCAL_POSITION_NED")
                self.add("autopilot_local_position_ned", view.time_boot_ms * 1000, p)
        except mc.CodecError as exc:
            rejected[f"{kind.lower()}_{exc.reason}"] += 1


NOTES = {
    "gnss": "estimated position vs the GNSS fixes (at their validity times) in the local frame",
    "sim_state_truth": "estimated position vs SIM_STATE truth",
    "autopilot_global_position": "estimated position vs the autopilot's GLOBAL_POSITION_INT "
    "(its altitude is MSL: vertical error includes the home altitude difference)",
    "autopilot_local_position_ned": "estimated position vs the autopilot's LOCAL_POSITION_NED "
    "(about the autopilot's own origin, not aligned)",
}


def replay(
    path: str | Path,
    method: str,
    *,
    home: LocalNedFrame | None = None,
    config: EstimatorConfig | None = None,
    rate_hz: float = 20.0,
    navigator: NavigatorFactory | None = None,
    progress: Callable[[int, int], None] | None = None,
    on_imu: ImuHook | None = None,
) -> ReplayResult:
    """Replay ``path`` through a navigator; ``rate_hz`` limits the estimate rows (0: every IMU).

    ``config`` is the real Navigator's configuration (None: ``EstimatorConfig`` defaults); a
    ``navigator`` factory (tests) replaces the real Navigator and ignores it.

    ``progress(position_bytes, size_bytes)`` is called now and then; ``on_imu(t_us, navigator)``
    after every IMU sample is pushed (telemetry, pacing; its time is not the estimator's).
    Raises UserError when the log holds nothing usable (no frames, no IMU, no good fix, no estimate).
    """
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: no such file")
    wall0 = time.perf_counter()
    fix0 = first_good_fix(path)
    if home is None:
        if fix0 is None:
            probe = read_tlog(path)
            frames = sum(1 for _ in probe)
            what = "no usable GPS_RAW_INT 3-D fix" if frames else "no readable MAVLink frames"
            raise UserError(f"{path}: {what} in {frames} frames{_describe_skips(probe)}")
        home = LocalNedFrame(fix0.lat_deg, fix0.lon_deg, fix0.alt_m)
    nav = navigator(method, home) if navigator is not None else default_navigator(method, home, config)
    reader = read_tlog(path, (*IMU_TYPES, *ATTITUDE_TYPES, GNSS_TYPE, *REFERENCE_TYPES))
    refs = _References(home)
    used: Counter[str] = Counter()
    rejected: Counter[str] = Counter()
    series = _Series()
    fixes: list[GnssFix] = []
    source = {"imu": "", "attitude": ""}
    feed = _Feed(nav, int(1e6 / rate_hz) if rate_hz > 0 else 0, series, on_imu)
    chunk: list[Any] = []
    last_imu_us = 0
    first_imu_us: int | None = None
    count = 0
    for _, view in reader:
        count += 1
        if progress is not None and count % 4096 == 0:
            progress(reader.position, reader.size)
        kind = view.get_type()
        if kind in REFERENCE_TYPES:
            refs.take(view, last_imu_us, rejected)
            continue
        group = "imu" if kind in IMU_TYPES else "attitude" if kind in ATTITUDE_TYPES else "gnss"
        if group != "gnss":
            if not source[group]:
                source[group] = kind
            elif source[group] != kind:
                used[f"{group}_other_source_ignored"] += 1
                continue
        try:
            sample = mc.decode_sample(view)
        except mc.CodecError as exc:
            rejected[f"{group}_{exc.reason}"] += 1
            continue
        used[group] += 1
        kind_of = type(sample)
        if kind_of is GnssFix and sample.fix_type >= MIN_FIX_TYPE_3D:  # type: ignore[union-attr]
            fixes.append(sample)  # type: ignore[arg-type]
        elif kind_of is ImuSample:
            last_imu_us = sample.t_us  # type: ignore[union-attr]
            first_imu_us = last_imu_us if first_imu_us is None else first_imu_us
        chunk.append(sample)
        if len(chunk) >= FEED_CHUNK:
            feed(chunk)
    feed(chunk)
    estimator_s = feed.estimator_s
    if progress is not None:
        progress(reader.size, reader.size)
    read_s = time.perf_counter() - wall0 - estimator_s
    if reader.frames == 0:
        raise UserError(f"{path}: no readable MAVLink frames{_describe_skips(reader)}")
    if not used["imu"]:
        raise UserError(f"{path}: no usable IMU samples ({'/'.join(IMU_TYPES)}) in {reader.frames} frames"
                        f"{_describe_skips(reader)}")
    t_us, table = series.arrays()
    if t_us.size == 0:
        raise UserError(f"{path}: the estimator never initialised ({used['gnss']} GNSS fixes, "
                        f"{used['imu']} IMU samples)")
    summary = _summary(path, method, home, reader, used, rejected, nav, t_us, table, refs, fixes,
                       (last_imu_us - (first_imu_us or 0)) / 1e6, read_s, estimator_s, source)
    summary["wall_s"] = time.perf_counter() - wall0
    summary["realtime_factor"] = summary["duration_s"] / summary["wall_s"]
    return ReplayResult(summary, t_us, table)


def _gnss_reference(fixes: list[GnssFix], frame: LocalNedFrame) -> tuple[np.ndarray, np.ndarray]:
    """Validity times and local positions of the 3-D fixes (one vectorised conversion)."""
    t = np.array([f.t_validity_us for f in fixes], dtype=np.int64)
    if not fixes:
        return t, np.zeros((0, 3))
    lla = np.array([(f.lat_deg, f.lon_deg, f.alt_m) for f in fixes])
    return t, frame.to_ned_m(lla[:, 0], lla[:, 1], lla[:, 2]).T


def _summary(
    path: Path, method: str, home: LocalNedFrame, reader: TlogReader, used: Counter[str],
    rejected: Counter[str], nav: NavigatorLike, t_us: np.ndarray, table: np.ndarray,
    refs: _References, fixes: list[GnssFix], duration_s: float, read_s: float, estimator_s: float,
    source: dict[str, str],
) -> dict[str, Any]:
    p_est = table[:, 0:3]
    references = {"gnss": _gnss_reference(fixes, home)}
    references.update({k: (np.array(t, dtype=np.int64), np.array(p)) for k, (t, p) in refs.series.items()})
    return {
        "file": str(path),
        "method": method,
        "home": {"lat_deg": home.home_lat_deg, "lon_deg": home.home_lon_deg, "alt_m": home.home_alt_m},
        "duration_s": duration_s,
        "sources": {k: v or None for k, v in source.items()},
        "samples_used": dict(used),
        "samples_rejected": {"codec": dict(rejected), "reader": dict(reader.skipped),
                             "reader_skipped_bytes": reader.skipped_bytes},
        "frames_read": reader.frames,
        "navigator": dict(nav.counters()),
        "estimates": int(t_us.size),
        "beta": _distribution(table[:, 9]),
        "nis": _distribution(table[:, 10]),
        "errors": {name: _error_stats(t, p, t_us, p_est, NOTES[name]) for name, (t, p) in references.items()},
        "timing_s": {"read_decode_output": read_s, "estimator": estimator_s},
    }


def json_safe(value: Any) -> Any:
    """NaN/inf -> None, recursively, so the summary is strict JSON."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_outputs(result: ReplayResult, out_dir: Path) -> None:
    import json

    out_dir.mkdir(parents=True, exist_ok=True)
    table = np.column_stack((result.t_us / 1e6, result.table))
    np.savetxt(out_dir / "estimates.csv", table, delimiter=",", fmt="%.9g",
               header=",".join(CSV_COLUMNS), comments="")
    (out_dir / "summary.json").write_text(json.dumps(json_safe(result.summary), indent=2) + "\n")
