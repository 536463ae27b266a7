"""Replay a log through the estimator: samples in arrival order, estimates and a summary out.

A reader (:mod:`gcs_tools.replay.logs`: MAVLink tlog, ArduPilot DataFlash ``.bin``, PX4 ULog
``.ulg``) yields domain samples and reference positions in arrival order; the samples are pushed
to a :class:`companion.estimator.Navigator`, the references (the autopilot's own estimate, truth)
and the fixes themselves are compared with the estimate online (:mod:`companion.metrics`).

Streaming: the tlog and DataFlash readers read in blocks; with ``out_dir`` the estimate rows are
written to ``estimates.csv`` as they come; β and NIS are summarised in fixed-size histograms.
What is kept grows only by the error vector of each reference sample (12 bytes) and, for the
figures, the fixes and references at up to 10 Hz (``TRACK_PERIOD_US``, 40 bytes a point).

Log restarts: a concatenated log (or an autopilot reboot inside one) makes the IMU time jump
back. The project's one clock rule decides (:mod:`companion.domain.clock_guard`,
:data:`RESTART_WINDOW`): a jump of more than 1 s back confirmed by 5 consecutive IMU samples on
the new time base starts a new segment: a fresh navigator (same frame), the comparisons
restarted; counters are summed over segments and ``log_restarts`` counts them. Events are held
while the rule decides. A lone sample far back is not a restart: it goes to the navigator,
which rejects it (``imu_rejected_time_backwards``). Forward, the IMU time may jump by up to
:data:`FORWARD_JUMP_US` (a logger paused); a jump beyond it is a new segment only when 5 samples
confirm it, and a lone sample that far ahead (a damaged stamp) is dropped and counted
(``imu_time_jump`` in ``samples_rejected.codec``) instead of moving the time on, which would
leave every later sample behind it.
"""

from __future__ import annotations

import time
from array import array
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Protocol

import numpy as np

from companion.domain.clock_guard import ClockWindow, StreamClock, Verdict
from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix, ImuSample, NavEstimate
from companion.errors import UserError
from companion.metrics import Distribution, PositionErrors
from companion.tight.samples import RawGnss
from gcs_tools.jsonvalues import plain_json
from gcs_tools.replay.events import AUTOPILOT, MIN_FIX_TYPE_3D, TRUTH, LocalReference, LogReader, Reference
from gcs_tools.replay.gnss_record import GnssRecord
from gcs_tools.replay.logs import open_log

if TYPE_CHECKING:
    from companion.estimator import EstimatorConfig
    from companion.mission import Mission
    from gcs_tools.replay.synthetic_gnss import GnssErrorOptions

# Decoded samples fed to the navigator at a time: one timer pair per chunk instead of per sample
# (the order, and so every estimate and counter, is unchanged).
FEED_CHUNK = 512
# IMU time going back by more than 1 s, or forward by more than FORWARD_JUMP_US, may be a log
# restart, once 5 IMU samples in a row (each at most 1 s after the previous) continue on the new
# time base; a lone sample out there is a damaged stamp
FORWARD_JUMP_US = 600_000_000
RESTART_WINDOW = ClockWindow(max_back_us=1_000_000, max_forward_us=FORWARD_JUMP_US, consensus_samples=5,
                             consensus_step_us=1_000_000)
RESTART_HOLD_MAX = 4096  # events held while deciding; past this the jump is not a restart
# β and NIS distributions in bounded memory: quantiles exact to half a bin (β: 5e-5;
# NIS: 0.05 % relative, log bins from 1e-6 to 1e6)
BETA_BINS = 10_000
NIS_RANGE = (1e-6, 1e6)
NIS_BINS = 27_640
# a reference between two estimate rows further apart than this (an IMU dropout) is not compared
MAX_GAP_US = 1_000_000
MAX_HOME_DISTANCE_M = 50_000.0  # a given home farther than this from the log's first fix: refused (as export)
# the fixes and reference positions kept for the figures: at most one per this interval per kind
# (10 Hz, 40 bytes a point: 1.4 MB an hour per kind)
TRACK_PERIOD_US = 100_000
CSV_COLUMNS = (
    "t_s", "p_n_m", "p_e_m", "p_d_m", "v_n_m_s", "v_e_m_s", "v_d_m_s", "b_n_m", "b_e_m", "b_d_m",
    "beta", "nis",
    "var_p_n_m2", "var_p_e_m2", "var_p_d_m2", "var_v_n_m2_s2", "var_v_e_m2_s2", "var_v_d_m2_s2",
    "var_b_n_m2", "var_b_e_m2", "var_b_d_m2", "segment",
)
GNSS_NOTE = "estimated position vs the GNSS fixes (at their validity times) in the local frame"
RAW_FIXES_NOTE = ("the synthetic fixes' own position vs the reference at their validity times and at "
                  "their arrival times (what a consumer of the raw fixes has, latency counted)")


class NavigatorLike(Protocol):
    def push(self, sample: Any) -> None: ...
    def estimate(self) -> NavEstimate | None: ...
    def counters(self) -> dict[str, int]: ...


NavigatorFactory = Callable[[str, LocalNedFrame], NavigatorLike]
ImuHook = Callable[[int, NavigatorLike], None]


def default_navigator(method: str, frame: LocalNedFrame, config: EstimatorConfig | None = None,
                      mission: Mission | None = None) -> NavigatorLike:
    """The real Navigator (``companion.wiring.navigator_for``): with ``mission`` its estimator config,
    plugin parameters and map; without, no map; ``config`` replaces the estimator config (None: the
    mission's, or the ``EstimatorConfig`` defaults, the real-log values)."""
    from companion.wiring import navigator_for

    return navigator_for(mission, method, config=config, frame=frame)


def _rows(estimates: list[NavEstimate], segment: int) -> np.ndarray:
    """(n, len(CSV_COLUMNS) - 1): the CSV columns after t_s."""
    e = estimates
    return np.column_stack((
        np.array([x.p_ned_m for x in e]), np.array([x.v_ned_m_s for x in e]),
        np.array([x.b_ned_m for x in e]), np.array([(x.beta, x.nis) for x in e]),
        np.array([x.cov_diag for x in e]),
        np.full(len(e), float(segment)),
    )).astype(float)


class _MemorySink:
    """Keeps the rows (API callers that want the arrays)."""

    def __init__(self) -> None:
        self.t_us: list[np.ndarray] = []
        self.rows: list[np.ndarray] = []

    def write(self, t_us: np.ndarray, rows: np.ndarray) -> None:
        self.t_us.append(t_us)
        self.rows.append(rows)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        if not self.rows:
            return np.zeros(0, dtype=np.int64), np.zeros((0, len(CSV_COLUMNS) - 1))
        return np.concatenate(self.t_us), np.concatenate(self.rows)

    def close(self) -> None:
        pass


class _CsvSink:
    """Writes ``estimates.csv`` as rows come; the file (and its directory) appear with the first row."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file: IO[str] | None = None

    def write(self, t_us: np.ndarray, rows: np.ndarray) -> None:
        if not rows.size:
            return
        if self._file is None:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self._file = open(self.path, "w")  # noqa: SIM115 - closed by close()
            except OSError as exc:
                raise UserError(f"--out {self.path.parent}: cannot write {self.path.name}: "
                                f"{exc.strerror or exc}") from None
            self._file.write(",".join(CSV_COLUMNS) + "\n")
        table = np.column_stack((t_us / 1e6, rows))
        np.savetxt(self._file, table, delimiter=",", fmt="%.9g")

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0, dtype=np.int64), np.zeros((0, len(CSV_COLUMNS) - 1))

    def close(self) -> None:
        if self._file is not None:
            self._file.close()


class _Track:
    """A kind's positions in the local frame (t_s, n, e, d, segment), at most one per ``TRACK_PERIOD_US``."""

    def __init__(self) -> None:
        self.rows = array("d")
        self._next_us = -(1 << 62)

    def add(self, t_us: int, p_ned_m: Any, segment: int) -> None:
        if t_us >= self._next_us or t_us < self._next_us - 2 * TRACK_PERIOD_US:  # a restart: keep going
            self._next_us = t_us + TRACK_PERIOD_US
            self.rows.extend((t_us / 1e6, float(p_ned_m[0]), float(p_ned_m[1]), float(p_ned_m[2]), segment))

    def array(self) -> np.ndarray:
        return np.frombuffer(self.rows, dtype=float).reshape(-1, 5).copy()


class _Comparisons:
    """Online error statistics against the fixes and the log's references.

    Geodetic positions are converted into the frame in batches (one vectorised geodesy call per
    ``BATCH`` positions or per feed), not one by one."""

    BATCH = 32

    def __init__(self, frame: LocalNedFrame, max_gap_us: int) -> None:
        self.frame, self.max_gap_us = frame, max_gap_us
        self.gnss = PositionErrors(max_gap_us=max_gap_us)
        self.geodetic: dict[tuple[str, str], PositionErrors] = {}
        self.local: dict[tuple[str, str], PositionErrors] = {}
        self._queue: list[tuple[PositionErrors, _Track, int, float, float, float]] = []
        self.tracks: dict[str, _Track] = {}  # "gnss", AUTOPILOT, TRUTH: for the figures
        self.segment = 0  # the log segment (restarts) the tracks' rows belong to

    def estimate(self, t_us: int, p_ned_m: Any, var_ned_m2: Any) -> None:
        self.gnss.add_estimate(t_us, p_ned_m)
        for m in (*self.geodetic.values(), *self.local.values()):
            m.add_estimate(t_us, p_ned_m, var_ned_m2)

    def fix(self, fix: GnssFix) -> None:
        if fix.fix_type >= MIN_FIX_TYPE_3D:
            self._geodetic(self.gnss, "gnss", fix.t_validity_us, fix.lat_deg, fix.lon_deg, fix.alt_m)

    def reference(self, ref: Reference | LocalReference) -> None:
        key = (ref.kind, ref.source)
        truth = ref.kind == TRUTH  # the reported accuracy's coverage: against the truth only
        if type(ref) is Reference:
            m = self.geodetic.get(key)
            if m is None:
                m = self.geodetic[key] = PositionErrors(max_gap_us=self.max_gap_us, coverage=truth)
            self._geodetic(m, ref.kind, ref.t_us, ref.lat_deg, ref.lon_deg, ref.alt_m)
        else:
            m = self.local.get(key)
            if m is None:
                m = self.local[key] = PositionErrors(max_gap_us=self.max_gap_us, coverage=truth)
            m.add_reference(ref.t_us, ref.p_ned_m)  # type: ignore[union-attr]
            self._track(ref.kind).add(ref.t_us, ref.p_ned_m, self.segment)  # type: ignore[union-attr]

    def _geodetic(self, m: PositionErrors, kind: str, t_us: int, lat: float, lon: float, alt: float) -> None:
        self._queue.append((m, self._track(kind), t_us, lat, lon, alt))
        if len(self._queue) >= self.BATCH:
            self.flush()

    def flush(self) -> None:
        queue, self._queue = self._queue, []
        if not queue:
            return
        lla = np.array([q[3:] for q in queue], dtype=float)
        ned = self.frame.to_ned_m(lla[:, 0], lla[:, 1], lla[:, 2]).T
        for (m, track, t_us, *_), p in zip(queue, ned, strict=True):
            m.add_reference(t_us, p)
            track.add(t_us, p, self.segment)

    def _track(self, kind: str) -> _Track:
        track = self.tracks.get(kind)
        if track is None:
            track = self.tracks[kind] = _Track()
        return track

    def restart(self) -> None:
        self.flush()
        self.segment += 1
        for m in (self.gnss, *self.geodetic.values(), *self.local.values()):
            m.restart()

    def summary(self, reader: LogReader) -> dict[str, Any]:
        self.flush()
        out = {"gnss": {"source": reader.sources.get("gnss"), "note": GNSS_NOTE, **self.gnss.statistics()}}
        for kind in (AUTOPILOT, TRUTH):
            info = reader.references.get(kind)
            if info is None:
                continue
            key = (kind, info.source)
            m = self.local.get(key) if key in self.local else self.geodetic.get(key)
            if m is not None:
                out[kind] = {"source": info.source, "note": info.note, **m.statistics(info.alignment)}
        return out


class _Run:
    """The navigator(s) of one replay: feeding, estimate rows, segments."""

    def __init__(self, make_nav: Callable[[], NavigatorLike], period_us: int, sink: Any,
                 comparisons: _Comparisons, on_imu: ImuHook | None, record: GnssRecord) -> None:
        self.make_nav, self.period_us, self.sink = make_nav, period_us, sink
        self.comparisons, self.on_imu, self.record = comparisons, on_imu, record
        self.nav = make_nav()
        self.counters: Counter[str] = Counter()
        self.segments: list[dict[str, Any]] = []
        self.segment = 0
        self.first_imu_us: int | None = None
        self.last_imu_us: int | None = None
        self.rows = 0
        self.beta = Distribution(0.0, 1.0, BETA_BINS)
        self.nis = Distribution(*NIS_RANGE, NIS_BINS, log=True)
        self.next_row_us = -1
        self.estimator_s = 0.0

    def feed(self, samples: list[Any]) -> None:
        push, estimate, on_imu = self.nav.push, self.nav.estimate, self.on_imu
        next_row_us, period_us = self.next_row_us, self.period_us
        out: list[NavEstimate] = []
        hook_s = 0.0
        t0 = time.perf_counter()
        record, nav = self.record, self.nav
        record_s = record.overhead_s
        for sample in samples:
            kind = type(sample)
            if kind is GnssFix or kind is RawGnss:  # pushed by the record, which notes the decision
                record.pushed(sample, nav)
                continue
            push(sample)
            if kind is ImuSample:
                if sample.t_us >= record.wait_until_us:  # a fix waited for this IMU time
                    record.imu(sample.t_us)
                if sample.t_us >= next_row_us:
                    est = estimate()
                    if est is not None:
                        next_row_us = sample.t_us + period_us
                        out.append(est)
                if on_imu is not None:  # telemetry / pacing: not the estimator's time
                    h0 = time.perf_counter()
                    on_imu(sample.t_us, self.nav)
                    hook_s += time.perf_counter() - h0
        self.estimator_s += time.perf_counter() - t0 - hook_s - (record.overhead_s - record_s)
        self.next_row_us = next_row_us
        samples.clear()
        if out:
            self._rows(out)
        self.comparisons.flush()

    def _rows(self, estimates: list[NavEstimate]) -> None:
        t_us = np.array([e.t_us for e in estimates], dtype=np.int64)
        rows = _rows(estimates, self.segment)
        self.sink.write(t_us, rows)
        comparisons = self.comparisons
        for e in estimates:  # the reported accuracy too: its coverage of the truth
            comparisons.estimate(e.t_us, e.p_ned_m, e.cov_diag)
        self.beta.add(rows[:, 9])
        self.nis.add(rows[:, 10])
        self.rows += len(estimates)

    def imu_time(self, t_us: int) -> None:
        if self.first_imu_us is None:
            self.first_imu_us = t_us
        if self.last_imu_us is None or t_us > self.last_imu_us:
            self.last_imu_us = t_us

    def end_segment(self) -> None:
        self.counters.update(self.nav.counters())
        first, last = self.first_imu_us, self.last_imu_us
        self.segments.append({"first_imu_s": None if first is None else first / 1e6,
                              "last_imu_s": None if last is None else last / 1e6,
                              "duration_s": 0.0 if first is None or last is None else (last - first) / 1e6,
                              "estimates": self.rows - sum(s["estimates"] for s in self.segments)})

    def restart(self) -> None:
        self.end_segment()
        self.record.restart()
        self.segment += 1
        self.nav = self.make_nav()
        self.first_imu_us = self.last_imu_us = None
        self.next_row_us = -1
        self.comparisons.restart()


@dataclass
class ReplayResult:
    summary: dict[str, Any]
    t_us: np.ndarray  # (N,) estimate times (empty when the rows were streamed to a file)
    table: np.ndarray  # (N, len(CSV_COLUMNS) - 1): the CSV columns after t_s
    # "gnss" (the 3-D fixes at their validity times), "autopilot_estimate", "truth" when the log has
    # them: (K, 5) rows t_s, n, e, d [m] in the replay's frame, segment; at most one per TRACK_PERIOD_US
    tracks: dict[str, np.ndarray] = field(default_factory=dict)
    # what the estimator did with each GNSS input (``gnss_record``): file name ("gnss_fixes.csv",
    # "gnss_epochs.csv") -> its columns; empty when the rows were streamed to files
    gnss: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)


def _check_home_near_flight(home: LocalNedFrame, fix0: GnssFix | None) -> None:
    """A given home (``--home``, ``--mission``'s) farther than ``MAX_HOME_DISTANCE_M`` from the log's
    first 3-D fix: one line (in a local frame thousands of km away the replay's numbers are wrong)."""
    if fix0 is None:
        return
    d_m = float(np.linalg.norm(home.to_ned_m(fix0.lat_deg, fix0.lon_deg, fix0.alt_m)))
    if not d_m <= MAX_HOME_DISTANCE_M:
        raise UserError(f"home {home.home_lat_deg:g},{home.home_lon_deg:g},{home.home_alt_m:g} (--home or "
                        f"--mission) is {d_m / 1000:,.0f} km from the log's first 3-D fix "
                        f"({fix0.lat_deg:.6f},{fix0.lon_deg:.6f}): the log was not flown there (give a "
                        "--home near it, or neither option: its first fix)")


def replay(
    path: str | Path,
    method: str,
    *,
    home: LocalNedFrame | None = None,
    mission: Mission | None = None,
    config: EstimatorConfig | None = None,
    rate_hz: float = 20.0,
    navigator: NavigatorFactory | None = None,
    progress: Callable[[int, int], None] | None = None,
    on_imu: ImuHook | None = None,
    out_dir: Path | None = None,
    gps_delay_ms: float | None = None,
    reader: LogReader | None = None,
    gnss: GnssErrorOptions | None = None,
) -> ReplayResult:
    """Replay ``path`` through a navigator; ``rate_hz`` limits the estimate rows (0: every IMU).

    ``mission`` configures the real Navigator (estimator section, plugins, map; None: the
    ``EstimatorConfig`` defaults, no map), ``config`` replaces its estimator config; a ``navigator``
    factory (tests) replaces the real Navigator. With ``out_dir`` the rows are streamed to
    ``out_dir/estimates.csv`` (the result's arrays are then empty); ``write_summary`` writes the
    summary. ``gps_delay_ms`` overrides a DataFlash log's GPS delay.
    ``gnss`` replaces the log's fixes by fixes made from its truth (or its own fixes) plus errors
    (:mod:`gcs_tools.replay.synthetic_gnss`); the summary then has ``synthetic_gnss`` and
    ``errors.raw_fixes`` (the fixes' own errors at their validity and arrival times).

    ``reader`` replaces the log's own reader (e.g. ``gcs_tools.gnss.replay``: the log with SPP fixes
    from RINEX, or smartLoc); ``path`` then only names the input in the summary.

    ``progress(position_bytes, size_bytes)`` is called now and then; ``on_imu(t_us, navigator)``
    after every IMU sample is pushed (telemetry, pacing; its time is not the estimator's).
    Raises UserError when the log holds nothing usable (no frames, no IMU, no good fix, no estimate).
    """
    path = Path(path)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    synthetic = None
    check_home = home is not None and gnss is None  # a given home, not the synthetic fixes' own frame
    if reader is not None:  # raw GNSS: the log with SPP fixes, or smartLoc
        if gnss is not None:
            raise UserError("synthetic GNSS (--gnss-errors) and raw GNSS both replace the log's fixes: "
                            "choose one")
    else:
        reader = open_log(path, gps_delay_ms, home)
        if gnss is not None:
            from gcs_tools.replay.synthetic_gnss import replace_gnss

            try:
                synthetic, home = replace_gnss(reader, open_log(path, gps_delay_ms, home), gnss, home)
            except UserError as exc:
                raise UserError(f"{path}: {exc}") from None
            reader = synthetic
        elif reader.sources.get("gnss") is None:
            raise UserError(f"{path}: {reader.describe_empty()}")
    if home is None:
        home = getattr(reader, "anchor", None)
    if home is None:
        fix0 = reader.first_fix()
        if fix0 is None:
            raise UserError(f"{path}: {reader.describe_empty()}")
        home = LocalNedFrame(fix0.lat_deg, fix0.lon_deg, fix0.alt_m)
    elif check_home:
        anchor = getattr(reader, "anchor", None)
        if anchor is None:
            _check_home_near_flight(home, reader.first_fix())
        elif reader.format != "ansfl":  # a geodetic anchor (raw GNSS: its first single-point solution)
            _check_home_near_flight(home, GnssFix(0, anchor.home_lat_deg, anchor.home_lon_deg,
                                                  anchor.home_alt_m, 3, 0))
    frame = home

    def make_nav() -> NavigatorLike:
        if navigator is not None:
            return navigator(method, frame)
        return default_navigator(method, frame, config, mission)

    sink: _MemorySink | _CsvSink = _MemorySink() if out_dir is None else _CsvSink(out_dir / "estimates.csv")
    period_us = int(1e6 / rate_hz) if rate_hz > 0 else 0
    comparisons = _Comparisons(frame, max(MAX_GAP_US, 4 * period_us))
    record = GnssRecord(frame, out_dir)
    run = _Run(make_nav, period_us, sink, comparisons, on_imu, record)
    try:
        restarts = _stream(reader, run, comparisons, progress)
        record.close()
    finally:
        sink.close()
        record.abandon()
    run.end_segment()
    st = reader.stats
    if progress is not None:
        progress(st.size, st.size)
    if st.records == 0:
        raise UserError(f"{path}: no readable records in the {reader.format} log")
    if not st.decoded["imu"]:
        raise UserError(f"{path}: no usable IMU samples ({reader.sources.get('imu') or 'none found'}) "
                        f"in {st.records} records")
    if run.rows == 0:
        refused = ", ".join(f"{k.replace('_', ' ')} {v:,}" for k, v in st.rejected.items() if v)
        by_nav = ", ".join(f"{k.removeprefix('gnss_rejected_').replace('_', ' ')} {v:,}"
                           for k, v in run.counters.items() if v and k.startswith("gnss_rejected_"))
        raise UserError(f"{path}: the estimator never initialised ({st.decoded['gnss']} GNSS fixes, "
                        f"{st.decoded['imu']} IMU samples"
                        + (f"; refused while reading: {refused}" if refused else "")
                        + (f"; GNSS refused by the estimator: {by_nav}" if by_nav else "") + ")")
    estimator_s = run.estimator_s
    wall_s = time.perf_counter() - wall0
    duration_s = sum(s["duration_s"] for s in run.segments)
    summary: dict[str, Any] = {
        "file": str(path),
        "format": reader.format,
        "method": method,
        "home": {"lat_deg": home.home_lat_deg, "lon_deg": home.home_lon_deg, "alt_m": home.home_alt_m},
        "duration_s": duration_s,
        "sources": dict(reader.sources),
        "samples_used": dict(st.decoded),
        "samples_rejected": {"codec": dict(st.rejected), "reader": dict(st.skipped),
                             "reader_skipped_bytes": st.skipped_bytes},
        "records_read": st.records,
        "navigator": dict(run.counters),
        "log_restarts": restarts,
        "segments": run.segments,
        "estimates": run.rows,
        "beta": run.beta.summary(),
        "nis": run.nis.summary(),
        "errors": comparisons.summary(reader),
        "timing_s": {"read_decode_output": wall_s - estimator_s, "estimator": estimator_s},
        "wall_s": wall_s,
        "cpu_s": time.process_time() - cpu0,
        "realtime_factor": duration_s / wall_s,
    }
    if synthetic is not None:
        summary["synthetic_gnss"] = synthetic.synthetic.info
        summary["errors"]["raw_fixes"] = {"note": RAW_FIXES_NOTE, **synthetic.raw_errors}
    log_reader: Any = reader  # the log's own reader, under any wrapper that replaces its GNSS
    while hasattr(log_reader, "inner"):
        log_reader = log_reader.inner
    clock = getattr(log_reader, "clock", None)
    if clock is not None:
        summary["clock_alignment"] = clock
    gps_delay = getattr(log_reader, "gps_delay_source", "")
    if gps_delay:
        summary["gnss_validity"] = {"gps_delay_ms": getattr(log_reader, "gps_delay_ms", None),
                                    "from": gps_delay}
    t_us, table = sink.arrays()
    return ReplayResult(summary, t_us, table, {k: v.array() for k, v in comparisons.tracks.items()},
                        record.arrays())


def _stream(reader: LogReader, run: _Run, comparisons: _Comparisons,
            progress: Callable[[int, int], None] | None) -> int:
    """Push the reader's events through ``run``; returns the number of log restarts."""
    chunk: list[Any] = []
    held: list[Any] = []  # events after a backward IMU jump, while the clock rule decides
    clock = StreamClock(RESTART_WINDOW)
    restarts = 0
    count = 0
    stats = reader.stats

    def far_ahead(ev: Any) -> bool:
        """An IMU sample beyond the time base's forward window (counted ``imu_time_jump``): a lone
        damaged stamp, never the stream's new time (a confirmed jump has moved the base to it)."""
        base = clock.base_us
        if type(ev) is not ImuSample or base is None or ev.t_us <= base + RESTART_WINDOW.max_forward_us:
            return False
        stats.rejected["imu_time_jump"] += 1
        return True

    def process(ev: Any) -> None:
        kind = type(ev)
        if kind is Reference or kind is LocalReference:
            comparisons.reference(ev)
            return
        if kind is ImuSample:
            run.imu_time(ev.t_us)
        elif kind is GnssFix:
            comparisons.fix(ev)
        chunk.append(ev)
        if len(chunk) >= FEED_CHUNK:
            run.feed(chunk)

    feed_chunk = FEED_CHUNK
    for ev in reader:
        count += 1
        if progress is not None and count % 4096 == 0:
            progress(stats.position, stats.size)
        kind = type(ev)
        if not held and kind is not ImuSample and kind is not GnssFix and kind is not Reference \
                and kind is not LocalReference:  # attitude: the common case, inline
            chunk.append(ev)
            if len(chunk) >= feed_chunk:
                run.feed(chunk)
            continue
        verdict = clock.check(ev.t_us) if type(ev) is ImuSample else None
        if held:
            held.append(ev)
            if verdict is Verdict.RESET:
                run.feed(chunk)
                run.restart()
                restarts += 1
            if verdict is Verdict.ACCEPT or verdict is Verdict.RESET or len(held) > RESTART_HOLD_MAX:
                pending, held = held, []  # back on the old time base (a lone outlier), or a restart
                for e in pending:
                    if not far_ahead(e):
                        process(e)
            continue
        if verdict is Verdict.REJECT:
            if clock.pending:  # far off: a restart, or a lone outlier?
                held = [ev]
            elif not far_ahead(ev):  # beyond any stamp (negative: the navigator counts it)
                process(ev)
            continue
        process(ev)
    for e in held:
        if not far_ahead(e):
            process(e)
    run.feed(chunk)
    return restarts


def json_safe(value: Any) -> Any:
    """NaN/inf -> None, recursively, so the summary is strict JSON."""
    return plain_json(value, nan_to_none=True)


def write_summary(result: ReplayResult, out_dir: Path) -> None:
    import json

    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps(json_safe(result.summary), indent=2) + "\n")


def write_outputs(result: ReplayResult, out_dir: Path) -> None:
    """estimates.csv from the in-memory rows, and summary.json."""
    out_dir.mkdir(parents=True, exist_ok=True)
    table = np.column_stack((result.t_us / 1e6, result.table))
    np.savetxt(out_dir / "estimates.csv", table, delimiter=",", fmt="%.9g",
               header=",".join(CSV_COLUMNS), comments="")
    write_summary(result, out_dir)
