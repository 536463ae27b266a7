"""Replace a log's GNSS by fixes made from its truth (or its own fixes) plus chosen errors.

"This flight, through a canyon": a real IMU and attitude, and fixes that a degraded receiver
would have delivered along the flown path. Per epoch (``rate_hz``, validity times on a regular
grid from the first base sample):

- **base** position: the log's truth (``truth``: ground truth / RTK, e.g. ANSFL ``GT.csv`` or
  a SITL log's ``SIM``) or the log's own fixes (``log``), linearly interpolated to the validity
  time; no fix where the base has a gap longer than ``MAX_BASE_GAP_S``;
- **error** (NED, m): ``none``; ``model``: the project's urban GNSS model
  (:class:`simvehicle.gnss.GnssModel`, eq. 22-27: Gauss-Markov multipath bias, white noise,
  and the effects beyond them that need no city, e.g. Student-t tails) at a fixed distance to the
  nearest building (``clearance_m``, 0 = a street canyon throughout), with its ``GnssConfig``
  fields overridable; or a recorded **error series** (CSV, :func:`load_error_series`), read from
  a seed-drawn start (``series_start_s`` to fix it), interpolated linearly between its epochs,
  with no fix where it has a gap (an outage) and wrapped around when shorter than the flight;
- **latency**: the model's latency process (eq. 27 at the clearance; 0.6 s mean in a canyon) or
  a fixed ``latency_ms``: a fix arrives (is pushed to the estimator, between IMU samples) at
  validity + latency;
- **velocity** (``velocity_std_m_s``, None = none): the base's velocity (central differences)
  plus white noise of that std per axis (ours: Doppler is far less affected by reflections than
  the range, but not unaffected);
- **accuracy** the fix reports: ``reported`` (h_acc = v_acc = the model's reported std, or the
  series' ``h_acc_m``/``v_acc_m``; speed accuracy = ``velocity_std_m_s``), ``none`` (NaN: the
  estimator falls back to its configured std), or ``eph`` (only an HDOP = h_acc / ``HDOP_UERE_M``,
  as receivers that report a DOP but no accuracy do).

Every draw comes from ``np.random.SeedSequence(seed).spawn(4)``: 0 the model's stream (bias,
noise, latency), 1 its unmodelled effects, 2 the velocity noise, 3 the series start.

The raw fixes are scored too (:func:`raw_fix_errors`): each fix's position against the reference
(the truth; the base when the log has none) at its validity time AND at its arrival time, so an
estimate is compared fairly with what a consumer of the raw fixes would have had (latency counted).
"""

from __future__ import annotations

import csv
import difflib
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix, ImuSample
from companion.errors import UserError
from companion.metrics import error_statistics
from gcs_tools.replay.events import MIN_FIX_TYPE_3D, TRUTH, Event, LocalReference, LogReader, Reference

if TYPE_CHECKING:
    from simvehicle.config import GnssConfig

SERIES_HEADER = ("t_s", "err_n_m", "err_e_m", "err_d_m", "h_acc_m", "v_acc_m")
ACCURACY_MODES = ("reported", "none", "eph")
BASES = ("truth", "log")
HDOP_UERE_M = 5.0  # (ours) user-equivalent range error: HDOP = h_acc / this in --gnss-accuracy eph
MAX_BASE_GAP_S = 1.0  # no fix valid inside a longer gap of the base track
SERIES_GAP_FACTOR = 1.6  # a series gap longer than this × its median period (an epoch missing) is an outage
MAX_RATE_HZ = 50.0
MAX_SERIES_ROWS = 10_000_000


@dataclass(frozen=True)
class GnssErrorOptions:
    """What replaces the log's GNSS (see the module doc)."""

    errors: str  # "none" | "model" | path of an error series CSV
    rate_hz: float = 5.0
    accuracy: str = "reported"
    latency_ms: float | None = None  # None: the model's latency process at clearance_m
    base: str | None = None  # "truth" | "log"; None: truth when the log has it, else the log's fixes
    clearance_m: float = 0.0  # the model's distance to the nearest building
    model_overrides: tuple[tuple[str, Any], ...] = ()  # GnssConfig fields, e.g. (("sigma_bias_max_m", 5.0),)
    velocity_std_m_s: float | None = 0.2
    seed: int = 0
    series_start_s: float | None = None  # None: drawn from the seed

    def check(self) -> None:
        """One-line errors for values no replay could use (before anything is read)."""
        if self.errors not in ("none", "model") and not Path(self.errors).is_file():
            near = difflib.get_close_matches(self.errors, ("none", "model"), n=1, cutoff=0.5)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise UserError(f"--gnss-errors {self.errors!r}: no such file, and not 'none' or 'model'{hint}")
        if not (0 < self.rate_hz <= MAX_RATE_HZ):
            raise UserError(f"--gnss-rate-hz {self.rate_hz}: expected > 0 and <= {MAX_RATE_HZ:g}")
        if self.accuracy not in ACCURACY_MODES:
            raise UserError(f"--gnss-accuracy {self.accuracy!r}: not one of {', '.join(ACCURACY_MODES)}")
        if self.latency_ms is not None and not (0 <= self.latency_ms <= 5000):
            raise UserError(f"--gnss-latency-ms {self.latency_ms}: expected 0 to 5000 ms")
        if self.base is not None and self.base not in BASES:
            raise UserError(f"--gnss-base {self.base!r}: not one of {', '.join(BASES)}")
        if not (math.isfinite(self.clearance_m) and self.clearance_m >= 0):
            raise UserError(f"--gnss-clearance-m {self.clearance_m}: expected a distance >= 0")
        if self.velocity_std_m_s is not None and not (0 <= self.velocity_std_m_s <= 100):
            raise UserError(f"--gnss-velocity {self.velocity_std_m_s}: expected 'none' or a std of 0 to "
                            "100 m/s")
        self.model_config()

    def model_config(self) -> GnssConfig:
        from companion.mission.schema import build
        from simvehicle.config import GnssConfig

        return build(GnssConfig, dict(self.model_overrides), "--gnss-set gnss")


def velocity_option(text: str) -> float | None:
    """``--gnss-velocity STD_M_S|none``: the fixes' velocity noise std, or None (no velocity); range checked
    by ``GnssErrorOptions.check``."""
    if text == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise UserError(f"--gnss-velocity {text!r}: expected a std in m/s or 'none'") from None


@dataclass(frozen=True)
class ErrorSeries:
    """A recorded GNSS error series: per epoch the fix's error (fix − truth, NED) and the accuracy
    the receiver reported (NaN where not given)."""

    t_s: np.ndarray  # (n,) increasing
    err_ned_m: np.ndarray  # (n, 3)
    h_acc_m: np.ndarray  # (n,)
    v_acc_m: np.ndarray  # (n,)

    @property
    def period_s(self) -> float:
        return float(np.median(np.diff(self.t_s)))


def _number(text: str, path: Path, line: int, column: str, optional: bool) -> float:
    text = text.strip()
    if not text and optional:
        return math.nan
    try:
        value = float(text)
    except ValueError:
        raise UserError(f"{path}: line {line}: {column} {text!r} is not a number") from None
    if not math.isfinite(value) or (optional and value < 0):
        raise UserError(f"{path}: line {line}: {column} {text!r}: expected a finite "
                        f"{'accuracy >= 0' if optional else 'number'}")
    return value


def load_error_series(path: str | Path) -> ErrorSeries:
    """Read an error series CSV: header ``t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m``, one row per
    epoch, times increasing; ``h_acc_m``/``v_acc_m`` may be empty. One-line errors naming the line."""
    p = Path(path)
    rows: list[tuple[float, ...]] = []
    try:
        with open(p, newline="", encoding="utf-8") as f:
            reader = csv.reader(f)
            header = tuple(h.strip() for h in next(reader, []))
            if header != SERIES_HEADER:
                raise UserError(f"{p}: header {','.join(header) or '(empty)'!r}; "
                                f"expected {','.join(SERIES_HEADER)}")
            for row in reader:
                line = reader.line_num
                if not row or not "".join(row).strip():
                    continue
                if len(row) != len(SERIES_HEADER):
                    raise UserError(f"{p}: line {line}: {len(row)} fields, expected {len(SERIES_HEADER)}")
                rows.append(tuple(_number(v, p, line, c, optional=c in ("h_acc_m", "v_acc_m"))
                                  for v, c in zip(row, SERIES_HEADER, strict=True)))
                if rows[-1][0] <= (rows[-2][0] if len(rows) > 1 else -math.inf):
                    raise UserError(f"{p}: line {line}: t_s {rows[-1][0]} is not after the previous row's")
                if len(rows) > MAX_SERIES_ROWS:
                    raise UserError(f"{p}: more than {MAX_SERIES_ROWS:,} rows")
    except OSError as exc:
        raise UserError(f"{p}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise UserError(f"{p}: not UTF-8 text") from None
    if len(rows) < 2:
        raise UserError(f"{p}: {len(rows)} rows; an error series needs at least 2")
    a = np.array(rows, dtype=float)
    return ErrorSeries(a[:, 0], a[:, 1:4], a[:, 4], a[:, 5])


@dataclass(frozen=True)
class Track:
    """Positions in the replay's frame over time (a log's truth, or its fixes)."""

    t_us: np.ndarray  # (k,) int64, increasing
    p_ned_m: np.ndarray  # (k, 3)
    label: str

    def at(self, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions (n, 3), covered (n,) bool): linear interpolation; not covered outside the
        track or inside a gap longer than MAX_BASE_GAP_S."""
        t = np.asarray(t_us, dtype=np.int64)
        tt = self.t_us
        i = np.clip(np.searchsorted(tt, t, side="right"), 1, len(tt) - 1)
        gap = tt[i] - tt[i - 1]
        covered = (t >= tt[0]) & (t <= tt[-1]) & (gap <= MAX_BASE_GAP_S * 1e6)
        p = np.column_stack([np.interp(t, tt, self.p_ned_m[:, k]) for k in range(3)])
        return p, covered

    def velocity_at(self, t_us: np.ndarray) -> np.ndarray:
        v = np.gradient(self.p_ned_m, self.t_us / 1e6, axis=0)
        return np.column_stack([np.interp(t_us, self.t_us, v[:, k]) for k in range(3)])


@dataclass(frozen=True)
class SyntheticFixes:
    """The fixes that replace the log's, in order of validity (arrays of one length)."""

    t_validity_us: np.ndarray  # (n,) int64
    t_arrival_us: np.ndarray  # (n,) int64
    p_ned_m: np.ndarray  # (n, 3) base + error
    err_ned_m: np.ndarray  # (n, 3) the error added to the base
    h_acc_m: np.ndarray  # (n,) what the fix reports (NaN = not reported)
    v_acc_m: np.ndarray
    hdop: np.ndarray
    v_ned_m_s: np.ndarray | None  # (n, 3) or None
    vel_acc_m_s: np.ndarray  # (n,)
    satellites: np.ndarray  # (n,) int
    info: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t_validity_us)

    def fixes(self, frame: LocalNedFrame) -> list[tuple[int, GnssFix]]:
        """(arrival µs, GnssFix in geodetic form about ``frame``) in order of arrival."""
        from simvehicle.gnss import NedToGeodetic

        to_geodetic = NedToGeodetic(frame)
        out = []
        for k in np.argsort(self.t_arrival_us, kind="stable").tolist():
            lat, lon, alt = to_geodetic(self.p_ned_m[k])
            v = None if self.v_ned_m_s is None else self.v_ned_m_s[k].copy()
            out.append((int(self.t_arrival_us[k]), GnssFix(
                int(self.t_validity_us[k]), lat, lon, alt, MIN_FIX_TYPE_3D, int(self.satellites[k]),
                h_acc_m=float(self.h_acc_m[k]), v_acc_m=float(self.v_acc_m[k]), hdop=float(self.hdop[k]),
                v_ned_m_s=v, vel_acc_m_s=float(self.vel_acc_m_s[k]))))
        return out


def epoch_grid(base: Track, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Validity times on the rate's grid from the first base sample, and the base there."""
    step_us = 1e6 / rate_hz
    t0, t1 = int(base.t_us[0]), int(base.t_us[-1])
    t = (t0 + np.rint(np.arange(0, (t1 - t0) / step_us + 1e-9) * step_us)).astype(np.int64)
    p, covered = base.at(t)
    return t[covered], p[covered]


def series_times(series_t_s: np.ndarray, span_s: float, start_s: float, offset_s: np.ndarray) -> np.ndarray:
    """The series time a flight reads ``offset_s`` after its first epoch: start + offset, wrapped around
    the series' ``span_s`` (the alignment rule of every recorded source)."""
    return series_t_s[0] + np.mod(start_s - series_t_s[0] + offset_s, span_s)


def _series_errors(series: ErrorSeries, t_us: np.ndarray, start_s: float) -> tuple[np.ndarray, ...]:
    """Errors, h_acc, v_acc at the epochs (series time = start + time since the first epoch, wrapped
    around the series' span), and which epochs fall in a series gap (outage)."""
    span = series.t_s[-1] - series.t_s[0] + series.period_s
    ts = series_times(series.t_s, span, start_s, (t_us - t_us[0]) / 1e6)
    i = np.clip(np.searchsorted(series.t_s, ts, side="right"), 1, len(series.t_s) - 1)
    t0, t1 = series.t_s[i - 1], series.t_s[i]
    inside = (ts >= series.t_s[0]) & (ts <= series.t_s[-1])
    outage = ~inside | (t1 - t0 > SERIES_GAP_FACTOR * series.period_s)
    w = np.clip((ts - t0) / (t1 - t0), 0.0, 1.0)[:, None]
    err = (1 - w) * series.err_ned_m[i - 1] + w * series.err_ned_m[i]
    nearer = np.where(w[:, 0] < 0.5, i - 1, i)
    return err, series.h_acc_m[nearer], series.v_acc_m[nearer], outage


def run_model(opts: GnssErrorOptions, t_v: np.ndarray, p_base: np.ndarray, frame: LocalNedFrame,
              period_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The urban model run along the epochs (validity times ``t_v`` µs, base positions, one epoch every
    ``period_s``) from the seed's streams 0 and 1: (its errors (n, 3), reported accuracy (n,), satellites
    (n,), arrival times (n,) µs from its latency process). Every error source takes its latency here."""
    from simvehicle.gnss import GnssModel
    from simvehicle.nlos import UnmodelledGnss

    seeds = np.random.SeedSequence(opts.seed).spawn(4)
    cfg = opts.model_config()
    unmodelled = None
    if opts.errors == "model" and cfg.unmodelled:  # no city: no NLOS, but tails and geometry noise
        unmodelled = UnmodelledGnss(cfg, np.zeros((0, 4)), np.zeros(0), np.random.default_rng(seeds[1]))
    model = GnssModel(cfg, period_s, frame, np.random.default_rng(seeds[0]), opts.clearance_m, unmodelled)
    n = len(t_v)
    err = np.zeros((n, 3))
    acc = np.full(n, math.nan)
    sats = np.zeros(n, dtype=int)
    t_arrival = np.zeros(n, dtype=np.int64)
    for k in range(n):  # the model's queue gives each fix its release time
        nf = model.sample(int(t_v[k]), p_base[k], opts.clearance_m)
        release = model.next_release_us
        model.release(int(release))
        t_arrival[k] = int(release)
        err[k] = nf.p_ned_m - p_base[k]
        acc[k] = model.reported_accuracy_m(nf)
        sats[k] = nf.satellites
    return err, acc, sats, t_arrival


def series_start(opts: GnssErrorOptions, series_t_s: np.ndarray, span_s: float) -> float:
    """Where a flight of ``span_s`` seconds starts reading a recorded series (times ``series_t_s``):
    ``opts.series_start_s``, else drawn uniformly from the seed's stream 3 so that the flight fits."""
    if opts.series_start_s is not None:
        return opts.series_start_s
    room = series_t_s[-1] - series_t_s[0] - span_s
    rng = np.random.default_rng(np.random.SeedSequence(opts.seed).spawn(4)[3])
    return float(series_t_s[0] + rng.uniform(0.0, max(room, 0.0)))


def synthesize(base: Track, opts: GnssErrorOptions, frame: LocalNedFrame) -> SyntheticFixes:
    """The fixes of ``opts`` along ``base`` (see the module doc)."""
    t_v, p_base = epoch_grid(base, opts.rate_hz)
    if not len(t_v):
        raise UserError(f"no GNSS epoch to make: the base ({base.label}) covers "
                        f"{(base.t_us[-1] - base.t_us[0]) / 1e6:.1f} s")
    n = len(t_v)
    err, h_acc, sats, t_arrival = run_model(opts, t_v, p_base, frame, 1.0 / opts.rate_hz)
    v_acc = h_acc.copy()
    info: dict[str, Any] = {"errors": opts.errors, "base": base.label, "rate_hz": opts.rate_hz,
                            "accuracy": opts.accuracy, "seed": opts.seed, "clearance_m": opts.clearance_m}
    keep = np.ones(n, dtype=bool)
    if opts.errors == "none":
        err[:] = 0.0
        h_acc[:] = v_acc[:] = math.nan
    elif opts.errors != "model":
        series = load_error_series(opts.errors)
        span_s = (t_v[-1] - t_v[0]) / 1e6
        start = series_start(opts, series.t_s, span_s)
        err, h_acc, v_acc, outage = _series_errors(series, t_v, start)
        keep = ~outage
        info.update(series_start_s=start, series_period_s=series.period_s,
                    series_span_s=float(series.t_s[-1] - series.t_s[0]),
                    series_outage_epochs=int(outage.sum()),
                    series_wrapped=bool(span_s > series.t_s[-1] - series.t_s[0]))
    else:
        info["model"] = {k: v for k, v in dict(opts.model_overrides).items()}
    return assemble(opts, base, t_v, p_base + err, err, h_acc, v_acc, sats, t_arrival, keep, info)


def assemble(opts: GnssErrorOptions, base: Track, t_v: np.ndarray, p_fix: np.ndarray, err: np.ndarray,
             h_acc: np.ndarray, v_acc: np.ndarray, sats: np.ndarray, t_arrival: np.ndarray, keep: np.ndarray,
             info: dict[str, Any]) -> SyntheticFixes:
    """The fixes at validity times ``t_v`` (positions ``p_fix`` = base + ``err``, what they report,
    the model's arrival times) with ``opts``' fixed latency, velocity (seed's stream 2) and accuracy mode
    applied; only the epochs ``keep`` are kept."""
    n = len(t_v)
    seeds = np.random.SeedSequence(opts.seed).spawn(4)
    if opts.latency_ms is not None:
        t_arrival = t_v + int(round(opts.latency_ms * 1000))
    latency_s = (t_arrival - t_v) / 1e6
    info["latency_s"] = {"source": "fixed" if opts.latency_ms is not None else "model (eq. 27)",
                         "mean": float(latency_s.mean()), "min": float(latency_s.min()),
                         "max": float(latency_s.max())}
    v_ned = None
    vel_acc = np.full(n, math.nan)
    if opts.velocity_std_m_s is not None:
        noise = np.random.default_rng(seeds[2]).standard_normal((n, 3)) * opts.velocity_std_m_s
        v_ned = base.velocity_at(t_v) + noise
        vel_acc[:] = opts.velocity_std_m_s
    hdop = np.full(n, math.nan)
    if opts.accuracy == "eph":
        hdop = h_acc / HDOP_UERE_M
    if opts.accuracy != "reported":
        h_acc, v_acc = np.full(n, math.nan), np.full(n, math.nan)
        vel_acc[:] = math.nan
    info["fixes"] = int(keep.sum())
    return SyntheticFixes(t_v[keep], t_arrival[keep], p_fix[keep], err[keep], h_acc[keep],
                          v_acc[keep], hdop[keep], None if v_ned is None else v_ned[keep], vel_acc[keep],
                          sats[keep], info)


def raw_fix_errors(fixes: SyntheticFixes, reference: Track) -> dict[str, Any]:
    """The fixes' own errors against ``reference`` at their validity and at their arrival times."""
    out: dict[str, Any] = {"reference": reference.label}
    for name, t in (("at_validity", fixes.t_validity_us), ("at_arrival", fixes.t_arrival_us)):
        p_ref, covered = reference.at(t)
        stats = error_statistics(fixes.p_ned_m[covered] - p_ref[covered])
        stats["unmatched"] = int((~covered).sum())
        out[name] = stats
    return out


@dataclass
class LogTracks:
    """What one pass over a log gives the synthesis: its truth and its 3-D fixes (raw: geodetic
    positions as (lat, lon, alt), local ones as NED in the replay's frame)."""

    truth_t_us: list[int] = field(default_factory=list)
    truth_p: list[tuple[float, float, float]] = field(default_factory=list)
    truth_geodetic: bool = True
    truth_label: str = ""
    fix_t_us: list[int] = field(default_factory=list)
    fix_p: list[tuple[float, float, float]] = field(default_factory=list)


def collect_tracks(reader: LogReader) -> LogTracks:
    out = LogTracks()
    for ev in reader:
        kind = type(ev)
        if kind is Reference and ev.kind == TRUTH:  # type: ignore[union-attr]
            out.truth_t_us.append(ev.t_us)  # type: ignore[union-attr]
            out.truth_p.append((ev.lat_deg, ev.lon_deg, ev.alt_m))  # type: ignore[union-attr]
            out.truth_label = f"truth ({ev.source})"  # type: ignore[union-attr]
        elif kind is LocalReference and ev.kind == TRUTH:  # type: ignore[union-attr]
            out.truth_t_us.append(ev.t_us)  # type: ignore[union-attr]
            out.truth_p.append(ev.p_ned_m)  # type: ignore[union-attr]
            out.truth_geodetic, out.truth_label = False, f"truth ({ev.source})"  # type: ignore[union-attr]
        elif kind is GnssFix and ev.fix_type >= MIN_FIX_TYPE_3D:  # type: ignore[union-attr]
            out.fix_t_us.append(ev.t_validity_us)  # type: ignore[union-attr]
            out.fix_p.append((ev.lat_deg, ev.lon_deg, ev.alt_m))  # type: ignore[union-attr]
    return out


def to_track(t_us: list[int], p: list[tuple[float, float, float]], label: str, geodetic: bool,
             frame: LocalNedFrame) -> Track:
    """Sorted by time, duplicates dropped, geodetic positions converted into ``frame``."""
    t = np.asarray(t_us, dtype=np.int64)
    a = np.asarray(p, dtype=float).reshape(-1, 3)
    if geodetic and len(a):
        a = frame.to_ned_m(a[:, 0], a[:, 1], a[:, 2]).T.reshape(-1, 3)
    order = np.argsort(t, kind="stable")
    t, a = t[order], a[order]
    keep = np.concatenate(([True], np.diff(t) > 0)) if len(t) else np.zeros(0, dtype=bool)
    return Track(t[keep], a[keep], label)


class WithSyntheticGnss:
    """A LogReader: ``inner``'s events with its fixes replaced by ``fixes``, each pushed before the
    first IMU sample at or after its arrival time (fixes arriving after the last IMU sample are
    counted, not pushed)."""

    def __init__(self, inner: LogReader, fixes: SyntheticFixes, frame: LocalNedFrame,
                 raw_errors: dict[str, Any]) -> None:
        self.inner, self.synthetic, self.frame = inner, fixes, frame
        self.format = inner.format
        self.stats = inner.stats
        self.sources = dict(inner.sources)
        errors = fixes.info["errors"]
        what = {"none": "no error", "model": "the urban model's errors"}.get(
            errors, f"the errors of {Path(errors).name}")
        self.sources["gnss"] = f"synthetic: {fixes.info['base']} + {what} at {fixes.info['rate_hz']:g} Hz"
        self.references = inner.references
        self.anchor = inner.anchor
        self.raw_errors = raw_errors
        self._fixes = fixes.fixes(frame)

    def first_fix(self) -> GnssFix | None:
        return self._fixes[0][1] if self._fixes else None

    def describe_empty(self) -> str:
        return self.inner.describe_empty()

    def __iter__(self) -> Iterator[Event]:
        pending, i, n = self._fixes, 0, len(self._fixes)
        decoded = self.stats.decoded
        for ev in self.inner:
            kind = type(ev)
            if kind is GnssFix:  # the inner reader counted it in "gnss": the synthetic fixes are
                decoded["gnss_log_fix_replaced"] += 1
                decoded["gnss"] -= 1
                continue
            if kind is ImuSample:
                while i < n and pending[i][0] <= ev.t_us:  # type: ignore[union-attr]
                    decoded["gnss"] += 1
                    yield pending[i][1]
                    i += 1
            yield ev
        if i < n:
            decoded["gnss_synthetic_after_last_imu"] += n - i

    # what the replay summary reports about the synthesis
    def summary(self) -> dict[str, Any]:
        return {**self.synthetic.info, "raw_fix_errors": self.raw_errors}


def replace_gnss(reader: LogReader, probe: LogReader, opts: GnssErrorOptions,
                 home: LocalNedFrame | None) -> tuple[WithSyntheticGnss, LocalNedFrame]:
    """``reader`` with its GNSS replaced by ``opts``' fixes, and the replay's frame (``home``, else
    the reader's anchor, else its first 3-D fix, else its first truth point). ``probe`` is a
    second reader of the same log: one pass over it gives the base track and the truth."""
    tracks = collect_tracks(probe)
    base = opts.base or ("truth" if tracks.truth_t_us else "log")
    if base == "truth" and not tracks.truth_t_us:
        raise UserError("--gnss-base truth: the log has no ground truth (SIM, SIM_STATE, *_groundtruth, "
                        "GT.csv); use --gnss-base log to degrade its own fixes")
    if base == "log" and not tracks.fix_t_us:
        if probe.stats.records == 0:  # not a flight log at all (a README, a RINEX file, ...)
            raise UserError(f"not a flight log (no readable {probe.format} records): nothing to make "
                            "fixes from")
        if opts.base is None:  # the default: not the user's --gnss-base
            raise UserError("the log has neither a ground truth nor a 3-D fix of its own to make the "
                            "fixes from")
        raise UserError("--gnss-base log: the log has no 3-D fix of its own")
    frame = home or reader.anchor
    if frame is None:
        first = tracks.fix_p[0] if tracks.fix_p else tracks.truth_p[0]
        frame = LocalNedFrame(*first)
    truth = to_track(tracks.truth_t_us, tracks.truth_p, tracks.truth_label, tracks.truth_geodetic, frame) \
        if tracks.truth_t_us else None
    own = (to_track(tracks.fix_t_us, tracks.fix_p, "the log's own fixes", True, frame)
           if tracks.fix_t_us else None)
    base_track = truth if base == "truth" else own
    assert base_track is not None
    if len(base_track.t_us) < 2:
        raise UserError(f"--gnss-base {base}: {len(base_track.t_us)} sample(s) in the log; at least 2 needed")
    fixes = synthesize(base_track, opts, frame)
    raw = raw_fix_errors(fixes, truth if truth is not None else base_track)
    return WithSyntheticGnss(reader, fixes, frame, raw), frame
