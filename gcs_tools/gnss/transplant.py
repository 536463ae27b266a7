"""A recorded urban sky on another vehicle's motion: smartLoc's per-satellite errors moved onto a flight.

"This real flight, through Berlin's satellites." A recorded error series (``synthetic_gnss``) gives a
flight only the drive's *fix* errors; here the flight gets the drive's *pseudoranges*, so a tightly
coupled filter can run on them with the flight's real IMU:

1. **Residuals at the truth** (:func:`drive_sky`): for each epoch of the smartLoc drive that has a
   single-point solution and a truth (the rows of its SPP error series, ``beliefnav gnss spp``), each
   observation's residual at the true position, ``baseline.epoch_residuals_at_truth``: pseudorange −
   |sat − truth| (Sagnac) − the receiver clock of its system, the clock being the median of
   ``pseudorange − range`` over that system's satellites above 40° (all of them when none is that high);
   with the satellite's direction, elevation, C/N0 and system.
2. **Placement** (:func:`place`): the flight's truth (NED about its first point) is placed in the local
   NED frame at the drive's first truth point (the satellites are 20 000 km away: a few hundred metres
   change their directions by ~10⁻⁵ rad), and drive epoch k is aligned to flight time by the series
   condition's rule (``synthetic_gnss``: the flight reads the drive from a seed-drawn start,
   ``series_start``, wrapped around the drive's span when longer); its pseudoranges become
   ``|sat − p_flight| (Sagnac) + clock + residual`` at the flight's truth at that time. The satellites'
   positions, C/N0, elevations and variances are the drive's. So the clock cancels: a placed pseudorange
   is the recorded one plus the change of geometric range, and the single-point solution minus the
   flight's truth reproduces the drive's SPP minus its truth up to the change of geometry (the
   known-answer test: below 5 cm on the drive).
3. **What the filters get**: the loosely coupled rows the single-point solutions (``SppConfig()``, as
   the series was made) as fixes with the series condition's latency, velocity and accuracy modes
   (``synthetic_gnss.assemble``); the tightly coupled rows the placed epochs as raw epochs, each
   arriving at the same time as its fix (its validity time + the same latency).

4. **Doppler** (:func:`range_rates_m_s`): smartLoc has none (its input rows carry no Doppler or range
   rate), so when the loose rows get a velocity (``velocity_std_m_s``, truth + that noise per axis) the
   placed epochs get synthetic pseudorange rates carrying the same information: the exact time derivative
   of the placed range (|sat − p| with its Sagnac term) at the flight's truth velocity (central
   differences of its truth, as the fixes' velocity) + the drive's receiver clock drift + white noise.
   Satellite velocities: central differences (second order, also at the ends) of the drive's satellite
   positions over its epochs; the drive's second differences match the ECEF orbital acceleration
   (gravity, centrifugal, Coriolis) to 2 mm/s² (median), so these velocities are good to well below
   1 mm/s, and the filters get the same ones. Clock drift: the least-squares slope of each system's clock
   at the truth over ±``DRIFT_WINDOW_S`` (the Berlin receiver: −49.7 m/s, ±0.5 m/s over the drive), the
   median over the epoch's systems. Noise: σ_i = k · 10^((45 − C/N0_i)/20), the simulated receiver's
   shape (``simvehicle.receiver``: thermal Doppler noise ∝ 10^((45 − C/N0)/20)), k chosen per epoch so
   that the weighted least-squares Doppler velocity (velocity and drift, those σ) has a mean per-axis
   variance of ``velocity_std_m_s``²: the loose rows' velocity noise, so both sides get the same
   information. Reflections' Doppler errors (a reflected signal's rate seen along its arrival
   direction) are not synthesised: the drive does not say which facade reflected, and the loose rows'
   velocity noise is white too. Seeded: the seed's stream 4 (``synthetic_gnss.assemble`` uses 0-3).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix
from companion.errors import UserError
from companion.gnss.constants import C_M_S, OMEGA_E_RAD_S
from companion.gnss.geometry import ecef_to_geodetic, ecef_to_ned_matrix, geodetic_to_ecef, sagnac_range_m
from companion.gnss.observations import GnssEpoch
from companion.gnss.spp import SppConfig
from gcs_tools.gnss.baseline import TruthResiduals, epoch_residuals_at_truth, ned_errors, solve_series
from gcs_tools.replay.events import TRUTH, Event, LocalReference, LogReader, Reference, ReferenceInfo

if TYPE_CHECKING:
    from gcs_tools.gnss.tight_replay import LogWithRawGnss
    from gcs_tools.replay.synthetic_gnss import GnssErrorOptions, SyntheticFixes, Track

PREFIX = "smartloc-sats:"  # the campaign's errors choice: smartloc-sats:DRIVE_Input.txt


@dataclass(frozen=True)
class DriveSky:
    """The drive's epochs with a single-point solution and a truth (its SPP error series' rows)."""

    t_s: np.ndarray  # (n,) series time: the epoch's time − the first kept epoch's (the series CSV's t_s)
    epochs: tuple[GnssEpoch, ...]
    truth_ecef_m: np.ndarray  # (n, 3)
    at_truth: tuple[TruthResiduals, ...]
    spp_err_ned_m: np.ndarray  # (n, 3) SPP − truth in ``origin``'s NED frame (the error series)
    origin: LocalNedFrame  # the truth at the drive's first epoch that has one
    name: str
    drift_m_s: np.ndarray  # (n,) the receiver clock drift (m/s; ``clock_drift_m_s``)
    rows_rejected: tuple[tuple[str, int], ...] = ()  # input rows skipped while reading, by reason

    @property
    def period_s(self) -> float:
        return float(np.median(np.diff(self.t_s)))

    @property
    def span_s(self) -> float:
        """The series' span as the series condition wraps it (last − first + one period)."""
        return float(self.t_s[-1] - self.t_s[0] + self.period_s)


def check_choice(text: str, option: str = "--errors") -> Path:
    """The smartLoc input of a ``smartloc-sats:INPUT`` choice given to ``option`` (one-line errors for a
    bad one)."""
    from gcs_tools.gnss.smartloc import default_truth_path

    path = Path(text[len(PREFIX):].strip())
    if not str(path) or str(path) == ".":
        raise UserError(f"{option} {text!r}: give the smartLoc input after '{PREFIX}' "
                        f"(e.g. {PREFIX}Berlin_Potsdamer_Platz_Input.txt)")
    if not path.is_file():
        raise UserError(f"{option} {text!r}: {path}: no such file")
    if default_truth_path(path) is None:
        raise UserError(f"{option} {text!r}: no *_GT.txt truth beside {path.name}")
    return path


def drive_sky(input_path: Path, config: SppConfig | None = None) -> DriveSky:
    """The drive of a smartLoc ``*_Input.txt`` (its ``*_GT.txt`` beside it), read and solved once per
    process while the files are unchanged (a campaign places it on many flights)."""
    from gcs_tools.gnss.smartloc import default_truth_path

    truth_path = default_truth_path(input_path)
    if truth_path is None:
        raise UserError(f"{input_path}: no *_GT.txt truth beside it")
    stamp = tuple((p.stat().st_mtime_ns, p.stat().st_size) for p in (input_path, truth_path))
    return _drive_sky(input_path.resolve(), config or SppConfig(), stamp)


@functools.lru_cache(maxsize=4)
def _drive_sky(input_path: Path, config: SppConfig, stamp: object) -> DriveSky:
    from gcs_tools.gnss import smartloc

    data, truth = smartloc.read_drive(input_path)
    series = solve_series(data.epochs, config)
    truth_ecef = truth.at(series.t_s)
    has_truth = np.isfinite(truth_ecef).all(axis=1)
    if not has_truth.any():
        raise UserError(f"{input_path}: no epoch inside its truth")
    p0 = truth_ecef[has_truth][0]
    lat, lon, h = (float(v) for v in ecef_to_geodetic(p0))
    origin = LocalNedFrame(math.degrees(lat), math.degrees(lon), h)
    err = ned_errors(series.p_ecef_m, truth_ecef, p0)
    keep = np.flatnonzero(np.isfinite(err).all(axis=1))
    if len(keep) < 2:
        raise UserError(f"{input_path}: {len(keep)} epoch(s) with a single-point solution and a truth")
    t_s = series.t_s[keep] - series.t_s[keep[0]]
    epochs = satellite_velocities(t_s, [data.epochs[i] for i in keep])
    at_truth = tuple(epoch_residuals_at_truth(e, p) for e, p in zip(epochs, truth_ecef[keep], strict=True))
    return DriveSky(t_s, epochs, truth_ecef[keep], at_truth, err[keep], origin, input_path.name,
                    clock_drift_m_s(t_s, epochs, at_truth), tuple(sorted(data.rejected.items())))


def satellite_velocities(t_s: np.ndarray, epochs: Sequence[GnssEpoch]) -> tuple[GnssEpoch, ...]:
    """``epochs`` with ``sat_vel_ecef_m_s``: each satellite's positions differentiated over the epochs
    that see it (``np.gradient``, second order inside and at the ends; NaN with fewer than 3 epochs)."""
    rows: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for k, e in enumerate(epochs):
        for j, key in enumerate(zip(e.system.tolist(), e.prn.tolist(), strict=True)):
            rows.setdefault(key, []).append((k, j))
    vel = [np.full((e.n, 3), np.nan) for e in epochs]
    for kj in rows.values():
        if len(kj) < 3:
            continue
        pos = np.array([epochs[k].sat_pos_ecef_m[j] for k, j in kj])
        v = np.gradient(pos, t_s[[k for k, _ in kj]], axis=0, edge_order=2)
        for (k, j), vk in zip(kj, v, strict=True):
            vel[k][j] = vk
    return tuple(e.replace(sat_vel_ecef_m_s=v) for e, v in zip(epochs, vel, strict=True))


DRIFT_WINDOW_S = 15.0  # the clock drift: the slope of the clock at the truth over ± this (a TCXO's drift
# wanders by tenths of m/s over tens of seconds; a shorter window follows the clock estimate's jumps)


def clock_drift_m_s(t_s: np.ndarray, epochs: Sequence[GnssEpoch], at_truth: Sequence[TruthResiduals],
                    window_s: float = DRIFT_WINDOW_S) -> np.ndarray:
    """(n,) the receiver clock drift (m/s) at each epoch: per system, the least-squares slope of its clock
    at the truth (``TruthResiduals.clock_m``) over the epochs within ±``window_s``; the median over the
    epoch's systems (their clocks differ by constant inter-system biases, not in drift)."""
    systems = sorted({int(s) for e in epochs for s in e.system.tolist()})
    slopes = np.full((len(epochs), len(systems)), np.nan)
    for col, s in enumerate(systems):
        k = np.array([i for i, e in enumerate(epochs) if (e.system == s).any()], dtype=int)
        if len(k) < 2:
            continue
        t = t_s[k]
        c = np.array([at_truth[i].clock_m[epochs[i].system == s][0] for i in k])
        for i, ti in zip(k.tolist(), t.tolist(), strict=True):
            m = np.abs(t - ti) <= window_s
            if m.sum() >= 2:
                tc = t[m] - t[m].mean()
                slopes[i, col] = float(np.dot(tc, c[m] - c[m].mean()) / np.dot(tc, tc))
    out = np.full(len(epochs), np.nan)
    seen = np.isfinite(slopes).any(axis=1)
    out[seen] = np.nanmedian(slopes[seen], axis=1)
    return out


CN0_REF_DBHZ = 45.0  # the simulated receiver's Doppler noise shape: σ ∝ 10^((45 − C/N0)/20)


def range_rates_m_s(epoch: GnssEpoch, p_ecef_m: np.ndarray, v_ecef_m_s: np.ndarray) -> np.ndarray:
    """(n,) the exact time derivative of ``sagnac_range_m`` (|sat − p| + ω (x_s y − y_s x) / c) for the
    satellites moving at ``epoch.sat_vel_ecef_m_s`` and the receiver at ``v_ecef_m_s``: the range rate of
    a placed pseudorange without clock, residual or noise."""
    rs, us, v = epoch.sat_pos_ecef_m, epoch.sat_vel_ecef_m_s, np.asarray(v_ecef_m_s, dtype=float)
    _, los = sagnac_range_m(rs, p_ecef_m)
    sagnac = OMEGA_E_RAD_S / C_M_S * (us[:, 0] * p_ecef_m[1] + rs[:, 0] * v[1]
                                      - us[:, 1] * p_ecef_m[0] - rs[:, 1] * v[0])
    return np.einsum("ij,ij->i", los, us - v) + sagnac


def doppler_sigma_m_s(epoch: GnssEpoch, p_ecef_m: np.ndarray, velocity_std_m_s: float) -> np.ndarray:
    """(n,) per-satellite rate σ ∝ 10^((45 − C/N0)/20), scaled so that the weighted least-squares velocity
    and drift from these rates has a mean per-axis velocity variance of ``velocity_std_m_s``² (NaN for a
    satellite without velocity; all NaN when fewer than 4 have one)."""
    ok = np.isfinite(epoch.sat_vel_ecef_m_s).all(axis=1)
    out = np.full(epoch.n, np.nan)
    if ok.sum() < 4:
        return out
    cn0 = np.where(np.isfinite(epoch.cn0_dbhz), epoch.cn0_dbhz, CN0_REF_DBHZ)
    shape = 10.0 ** ((CN0_REF_DBHZ - cn0) / 20.0)
    _, los = sagnac_range_m(epoch.sat_pos_ecef_m[ok], p_ecef_m)
    h = np.column_stack((-los, np.ones(int(ok.sum()))))
    q = np.linalg.inv(h.T @ (h / shape[ok, None] ** 2))
    out[ok] = shape[ok] * velocity_std_m_s / math.sqrt(float(np.trace(q[:3, :3])) / 3.0)
    return out


def ned_to_ecef(frame: LocalNedFrame, p_ned_m: np.ndarray) -> np.ndarray:
    """(n, 3) positions NED about ``frame``'s home in ECEF (the tangent frame, exact)."""
    lat, lon = math.radians(frame.home_lat_deg), math.radians(frame.home_lon_deg)
    p0 = geodetic_to_ecef(lat, lon, frame.home_alt_m)
    return p0 + np.asarray(p_ned_m, dtype=float).reshape(-1, 3) @ ecef_to_ned_matrix(lat, lon)


def place_epoch(epoch: GnssEpoch, at: TruthResiduals, p_ecef_m: np.ndarray,
                rate_m_s: np.ndarray | None = None) -> GnssEpoch:
    """``epoch`` as received at ``p_ecef_m``: pseudorange = |sat − p| (Sagnac) + clock + residual; with
    ``rate_m_s`` its pseudorange rates (else none: NaN)."""
    rho, _ = sagnac_range_m(epoch.sat_pos_ecef_m, p_ecef_m)
    rate = np.full(epoch.n, np.nan) if rate_m_s is None else rate_m_s
    return epoch.replace(pseudorange_m=rho + at.clock_m + at.residual_m, pseudorange_rate_m_s=rate)


def aligned_offsets_s(sky: DriveSky, start_s: float, flight_span_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(offsets from the flight's first epoch (s), drive epoch indices) in time order: the inverse of the
    series condition's rule, series time = t₀ + ((start − t₀ + offset) mod span); every drive epoch whose
    offset falls in [0, ``flight_span_s``] (more than once when the flight is longer than the drive)."""
    base = np.mod(sky.t_s - start_s, sky.span_s)
    laps = int(math.floor(flight_span_s / sky.span_s)) + 1
    off = np.concatenate([base + j * sky.span_s for j in range(laps)])
    idx = np.tile(np.arange(len(sky.t_s)), laps)
    keep = off <= flight_span_s + 1e-9
    order = np.argsort(off[keep], kind="stable")
    return off[keep][order], idx[keep][order]


@dataclass(frozen=True)
class PlacedSky:
    """The drive's epochs placed on a flight (arrays of one length, in flight time order)."""

    t_validity_us: np.ndarray  # (m,) int64 the flight's boot time
    drive_index: np.ndarray  # (m,) the drive epoch (``DriveSky`` row)
    epochs: tuple[GnssEpoch, ...]  # pseudoranges at the flight's truth
    p_truth_ned_m: np.ndarray  # (m, 3) the flight's truth there (the frame's NED)
    start_s: float  # where the flight reads the drive (series time)
    wrapped: bool
    rate_sigma_m_s: np.ndarray  # (m,) per epoch the median σ of its synthetic rates (NaN: no rates)


def place(sky: DriveSky, truth: Track, frame: LocalNedFrame, opts: GnssErrorOptions,
          residual_scale: float = 1.0) -> PlacedSky:
    """The drive placed on ``truth`` (in ``frame``: the drive's ``origin``): the flight's span and start
    are the series condition's with ``opts`` (its rate's grid, ``synthetic_gnss.series_start`` from its
    seed or its ``series_start_s``); ``residual_scale`` 0 gives error-free pseudoranges (a test). With a
    velocity (``opts.velocity_std_m_s`` not None) the epochs carry synthetic pseudorange rates at the truth's
    velocity (``Track.velocity_at``) with the drive's clock drift and noise of the same information
    (``doppler_sigma_m_s``; the seed's stream 4); without, none."""
    from gcs_tools.replay.synthetic_gnss import epoch_grid, series_start

    t_grid, _ = epoch_grid(truth, opts.rate_hz)
    if not len(t_grid):
        raise UserError(f"no GNSS epoch to make: the truth covers "
                        f"{(truth.t_us[-1] - truth.t_us[0]) / 1e6:.1f} s")
    span_s = (t_grid[-1] - t_grid[0]) / 1e6
    start = series_start(opts, sky.t_s, span_s)
    off, idx = aligned_offsets_s(sky, start, span_s)
    t_us = t_grid[0] + np.rint(off * 1e6).astype(np.int64)
    p_ned, covered = truth.at(t_us)
    t_us, idx, p_ned = t_us[covered], idx[covered], p_ned[covered]
    p_ecef = ned_to_ecef(frame, p_ned)
    std = opts.velocity_std_m_s
    lat, lon = math.radians(frame.home_lat_deg), math.radians(frame.home_lon_deg)
    v_ecef = truth.velocity_at(t_us) @ ecef_to_ned_matrix(lat, lon)
    rng = np.random.default_rng(np.random.SeedSequence(opts.seed).spawn(5)[4])
    epochs = []
    sigma_med = np.full(len(idx), np.nan)
    for i, (k, p) in enumerate(zip(idx.tolist(), p_ecef, strict=True)):
        at = sky.at_truth[k]
        if residual_scale != 1.0:
            at = dataclasses.replace(at, residual_m=at.residual_m * residual_scale)
        ep = sky.epochs[k]
        rate = None
        if std is not None:
            sigma = doppler_sigma_m_s(ep, p, std)
            rate = range_rates_m_s(ep, p, v_ecef[i]) + sky.drift_m_s[k] + sigma * rng.standard_normal(ep.n)
            sigma_med[i] = float(np.nanmedian(sigma)) if np.isfinite(sigma).any() else math.nan
        epochs.append(place_epoch(ep, at, p, rate))
    return PlacedSky(t_us, idx, tuple(epochs), p_ned, start, bool(span_s > sky.t_s[-1] - sky.t_s[0]),
                     sigma_med)


@dataclass(frozen=True)
class SkyOnFlight:
    """What a replay of one flight under the placed sky needs."""

    placed: PlacedSky
    fixes: SyntheticFixes  # the single-point solutions (every epoch with one)
    raw_arrival_us: np.ndarray  # (m,) when each placed epoch reaches the filter (its fix's arrival)
    frame: LocalNedFrame
    truth: Track  # the flight's truth in ``frame``
    raw_errors: dict[str, Any]  # the fixes' own errors (synthetic_gnss.raw_fix_errors)


def sky_on_flight(flight: Path, sky: DriveSky, opts: GnssErrorOptions, gps_delay_ms: float | None = None
                  ) -> SkyOnFlight:
    """The drive ``sky`` placed on the truth of the log ``flight`` (an ANSFL flight, or any log with a
    truth: ``on_drive_frame``) with the series condition's options ``opts`` (``GnssErrorOptions``: seed,
    rate, accuracy, latency, velocity)."""
    from gcs_tools.replay.synthetic_gnss import assemble, collect_tracks, raw_fix_errors, run_model, to_track

    frame = sky.origin
    tracks = collect_tracks(on_drive_frame(flight, gps_delay_ms, sky))
    if len(tracks.truth_t_us) < 2:
        raise UserError(f"{flight}: no ground truth (GT.csv, SIM, SIM_STATE, *_groundtruth) to place the "
                        "drive's satellites on")
    truth = to_track(tracks.truth_t_us, tracks.truth_p, tracks.truth_label, tracks.truth_geodetic, frame)
    placed = place(sky, truth, frame, opts)
    series = solve_series(placed.epochs, SppConfig())
    lat, lon = math.radians(frame.home_lat_deg), math.radians(frame.home_lon_deg)
    p0 = geodetic_to_ecef(lat, lon, frame.home_alt_m)
    p_fix = (series.p_ecef_m - p0) @ ecef_to_ned_matrix(lat, lon).T
    t_v = placed.t_validity_us
    # the series condition's latency process (its bias and noise unused), one epoch per drive period
    _, _, _, t_arrival = run_model(opts, t_v, placed.p_truth_ned_m, frame, sky.period_s)
    info: dict[str, Any] = {"errors": f"{PREFIX}{sky.name}", "base": truth.label,
                            "rate_hz": 1.0 / sky.period_s,
                            "accuracy": opts.accuracy, "seed": opts.seed, "series_start_s": placed.start_s,
                            "series_period_s": sky.period_s, "series_span_s": float(sky.t_s[-1] - sky.t_s[0]),
                            "series_wrapped": placed.wrapped, "epochs": len(t_v),
                            "epochs_without_solution": int((~series.ok).sum()),
                            "doppler": None if opts.velocity_std_m_s is None else {
                                "synthetic": True, "velocity_std_m_s": opts.velocity_std_m_s,
                                "rate_sigma_median_m_s": float(np.nanmedian(placed.rate_sigma_m_s)),
                                "clock_drift_median_m_s": float(np.nanmedian(sky.drift_m_s))}}
    err = p_fix - placed.p_truth_ned_m
    fixes = assemble(opts, truth, t_v, p_fix, err, series.h_acc_m, series.v_acc_m, series.n_used, t_arrival,
                     series.ok, info)
    raw_arrival = t_arrival if opts.latency_ms is None else t_v + int(round(opts.latency_ms * 1000))
    return SkyOnFlight(placed, fixes, raw_arrival, frame, truth, raw_fix_errors(fixes, truth))


def on_drive_frame(path: Path, gps_delay_ms: float | None, sky: DriveSky) -> LogReader:
    """The log ``path`` moved to the drive: its truth and references as NED about the drive's ``origin``.
    A log with local data only (ANSFL: an ``anchor``) is read in that frame; a log with geodetic
    references (a SITL truth, an autopilot's estimate) is read in its own frame, the one at its first
    truth point (found by reading up to it), and moved (``MovedReferences``: the flight keeps its shape,
    not its place). Fixes are the replay's to replace."""
    from gcs_tools.replay.logs import open_log

    reader = open_log(path, gps_delay_ms, sky.origin)
    if reader.anchor is not None:
        return reader
    first = next((ev for ev in open_log(path, gps_delay_ms) if type(ev) is Reference and ev.kind == TRUTH),
                 None)
    own = None if first is None else LocalNedFrame(first.lat_deg, first.lon_deg, first.alt_m)
    return MovedReferences(reader, sky.origin, own)


class MovedReferences:
    """A log reader whose geodetic references become ``LocalReference`` NED about ``own`` (the log's frame;
    None: its first reference), read as NED about ``anchor`` (the replay's home): the flight translated to
    another place on Earth (its vertical references' offsets, e.g. a truth logged at altitude 0, kept)."""

    def __init__(self, inner: LogReader, anchor: LocalNedFrame, own: LocalNedFrame | None = None) -> None:
        self.inner, self.anchor, self.own = inner, anchor, own
        self.format, self.stats, self.sources = inner.format, inner.stats, inner.sources
        self.references: dict[str, ReferenceInfo] = inner.references

    def first_fix(self) -> GnssFix | None:
        return None

    def describe_empty(self) -> str:
        return self.inner.describe_empty()

    def __iter__(self) -> Iterator[Event]:
        own = self.own
        for ev in self.inner:
            if type(ev) is Reference:
                if own is None:
                    own = LocalNedFrame(ev.lat_deg, ev.lon_deg, ev.alt_m)
                n, e, d = (float(v) for v in own.to_ned_m(ev.lat_deg, ev.lon_deg, ev.alt_m))
                yield LocalReference(ev.kind, ev.t_us, (n, e, d), ev.source)
            else:
                yield ev


def placed_raw_reader(inner: LogReader, on: SkyOnFlight, name: str) -> LogWithRawGnss:
    """``inner`` (in the drive's frame, ``on_drive_frame``) with its fixes replaced by the placed epochs
    as raw epochs, each pushed at its fix's arrival (``SkyOnFlight.raw_arrival_us``)."""
    from companion.tight import RawGnss
    from gcs_tools.gnss.tight_replay import LogWithRawGnss

    p = on.placed
    raws = [RawGnss(int(t), e) for t, e in zip(p.t_validity_us, p.epochs, strict=True)]
    arrival = dict(zip(p.t_validity_us.tolist(), on.raw_arrival_us.tolist(), strict=True))
    return LogWithRawGnss(inner, raws, on.frame, f"smartLoc {name} placed on the flight (raw epochs)",
                          lambda r: arrival[r.t_us])
