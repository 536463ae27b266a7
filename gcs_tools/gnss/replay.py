"""Raw GNSS into ``beliefnav replay``: single-point fixes in place of the log's own (loose coupling),
and smartLoc as a GNSS-only replay scored against its truth.

``LogWithFixes(reader, fixes)`` wraps a log reader: the log's GnssFix events are dropped (counted
as ``stats.rejected['log_fix_replaced']``) and the given fixes are inserted, in validity order, as
soon as the log's IMU time reaches their validity time (``LogWithGnss``, which
``tight_replay.LogWithRawGnss`` shares). ``SmartLocSource`` is a reader of its own:
a constant level attitude and a zero-acceleration IMU at 50 Hz (no inertial data: the filter runs
as a constant-velocity GNSS filter), the SPP fixes, and the smartLoc truth as references.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, TypeVar

import numpy as np

from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
from companion.errors import UserError, not_one_of
from companion.gnss.constants import C_M_S
from companion.gnss.fix import to_fix
from companion.gnss.geometry import ecef_to_geodetic
from companion.gnss.spp import SppConfig
from companion.gnss.systems import System
from companion.gnss.timescale import BootTimeMap
from gcs_tools.gnss.baseline import SppSeries, solve_series
from gcs_tools.replay.events import TRUTH, Event, LogReader, ReaderStats, Reference, ReferenceInfo

COUPLINGS = ("loose", "tight")
SMARTLOC_IMU_HZ = 50.0
SMARTLOC_T0_US = 1_000_000  # boot time of the drive's first epoch (IMU starts at 0)


def smartloc_boot_us(t_s: Any, t0_s: float) -> Any:
    """smartLoc seconds (epochs, odometry, truth) on the replay's boot time: ``SMARTLOC_T0_US`` at the
    drive's first epoch ``t0_s``, rounded to the nearest µs (an int for a float, int64 for an array).
    The data set's stamps are a millisecond grid written as decimal seconds with up to 0.17 µs of
    floating-point error either way (e.g. 281.99899983 for 281.999): rounding lands every stamp on its
    millisecond, truncation put 62 % of the Berlin drive's 1 µs early. The one rule of both readers."""
    us = np.rint((np.asarray(t_s, dtype=float) - t0_s) * 1e6).astype(np.int64) + SMARTLOC_T0_US
    return int(us) if us.ndim == 0 else us
GRAVITY_M_S2 = 9.80665


def check_coupling(coupling: str) -> None:
    if coupling not in COUPLINGS:
        raise not_one_of("--coupling", coupling, COUPLINGS)


def validity_gps_s(series: SppSeries) -> np.ndarray:
    """GPS time each solution is valid at: the receiver's time tag minus its (GPS) clock offset."""
    out = series.t_s.copy()
    for i, s in enumerate(series.solutions):
        if s.ok and len(s.clock_bias_m):
            k = s.clock_systems.index(System.GPS) if System.GPS in s.clock_systems else 0
            out[i] -= s.clock_bias_m[k] / C_M_S
    return out


def fixes_on_boot_time(series: SppSeries, time_map: BootTimeMap) -> list[GnssFix]:
    t_valid = validity_gps_s(series)
    fixes = []
    for t, s in zip(t_valid, series.solutions, strict=True):
        f = to_fix(s, time_map.boot_us(float(t)))
        if f is not None:
            fixes.append(f)
    return fixes


T = TypeVar("T")


class LogWithGnss(Generic[T]):
    """A log reader whose GNSS fixes are replaced by ``items`` (``what``: fixes or raw epochs, each at
    ``t_us(item)`` on boot time): the log's fixes are dropped (``log_fix_replaced``), each item is
    yielded before the first IMU sample at or after its time (``gnss_external``); those after the
    log's end are counted (``external_{what}_after_log``)."""

    def __init__(self, inner: LogReader, items: Sequence[T], t_us: Callable[[T], int], source: str,
                 what: str) -> None:
        self.inner = inner
        self.items = sorted(items, key=t_us)
        self._t_us = t_us
        self.format = inner.format
        self.stats: ReaderStats = inner.stats
        self.sources = dict(inner.sources)
        self.sources["gnss"] = source
        self._source = source
        self._what = what

    @property
    def references(self) -> dict[str, ReferenceInfo]:
        return self.inner.references

    def first_fix(self) -> GnssFix | None:
        return None

    def describe_empty(self) -> str:
        return f"no {self._what} from {self._source}"

    def __iter__(self) -> Iterator[Event | T]:
        items, i, n, t_us = self.items, 0, len(self.items), self._t_us
        for ev in self.inner:
            if type(ev) is GnssFix:  # the inner reader counted it in "gnss": the external items are
                self.stats.rejected["log_fix_replaced"] += 1
                self.stats.decoded["gnss"] -= 1
                continue
            if isinstance(ev, ImuSample):
                while i < n and t_us(items[i]) <= ev.t_us:
                    self.stats.decoded["gnss_external"] += 1
                    self.stats.decoded["gnss"] += 1
                    yield items[i]
                    i += 1
            yield ev
        self.stats.rejected[f"external_{self._what}_after_log"] += n - i


class LogWithFixes(LogWithGnss[GnssFix]):
    """A log reader whose GNSS fixes are replaced by ``fixes`` (validity-stamped on boot time)."""

    def __init__(self, inner: LogReader, fixes: Sequence[GnssFix], source: str) -> None:
        super().__init__(inner, fixes, lambda f: f.t_validity_us, source, "fix")
        self.fixes = self.items

    def first_fix(self) -> GnssFix | None:
        return self.fixes[0] if self.fixes else None


@dataclass
class SmartLocSource:
    """smartLoc as a replay reader (GNSS only: see the module doc)."""

    fixes: list[GnssFix]
    truth_t_s: np.ndarray
    truth_ecef_m: np.ndarray
    t0_s: float  # the drive's first epoch time (data set seconds) = boot SMARTLOC_T0_US
    truth_source: str = "smartLoc point3"  # what the truth rows are (gcs_tools.gnss.truth)

    format: str = "smartloc"

    def __post_init__(self) -> None:
        self.stats = ReaderStats()
        self.sources: dict[str, str | None] = {
            "imu": "none (zero acceleration, level)",
            "attitude": "none (level)",
            "gnss": "smartLoc pseudoranges -> SPP",
        }
        self.references = {
            TRUTH: ReferenceInfo(
                self.truth_source, "geodetic", "estimated position vs the smartLoc truth (ECEF -> geodetic)"
            )
        }

    def first_fix(self) -> GnssFix | None:
        return self.fixes[0] if self.fixes else None

    def describe_empty(self) -> str:
        return "no single-point solution in the smartLoc input"

    def __iter__(self) -> Iterator[Event]:
        lat, lon, h = ecef_to_geodetic(self.truth_ecef_m)
        t_ref_us = smartloc_boot_us(self.truth_t_s, self.t0_s)
        ends = [f.t_validity_us for f in self.fixes[-1:]] + [int(t_ref_us[-1])]
        t_end = max(ends) + 1_000_000
        step = int(1e6 / SMARTLOC_IMU_HZ)
        q = np.array([1.0, 0.0, 0.0, 0.0])
        acc = np.array([0.0, 0.0, -GRAVITY_M_S2])
        gyro = np.zeros(3)
        fi = ri = 0
        nf, nr = len(self.fixes), len(t_ref_us)
        for t in range(0, t_end, step):
            while ri < nr and t_ref_us[ri] <= t:
                yield Reference(
                    TRUTH,
                    int(t_ref_us[ri]),
                    float(np.degrees(lat[ri])),
                    float(np.degrees(lon[ri])),
                    float(h[ri]),
                    self.truth_source,
                )
                ri += 1
            while fi < nf and self.fixes[fi].t_validity_us <= t:
                self.stats.decoded["gnss"] += 1
                yield self.fixes[fi]
                fi += 1
            self.stats.decoded["imu"] += 1
            self.stats.records += 1
            yield AttitudeSample(t, q)
            yield ImuSample(t, acc, gyro)


def smartloc_source(input_path: Path, truth_path: Path | None, config: SppConfig) -> SmartLocSource:
    from gcs_tools.gnss import smartloc

    data, truth = smartloc.read_drive(input_path, truth_path)
    series = solve_series(data.epochs, config)
    t0 = float(series.t_s[0])
    fixes = []
    for t, s in zip(series.t_s, series.solutions, strict=True):
        f = to_fix(s, smartloc_boot_us(t, t0))
        if f is not None:
            fixes.append(f)
    src = SmartLocSource(fixes, truth.t_s, truth.p_ecef_m, t0, smartloc.truth_label(truth))
    src.stats.rejected.update(smartloc.rows_rejected(data.rejected))
    src.stats.rejected.update(smartloc.rows_rejected(truth.rejected, "truth_row"))
    return src


def rinex_log_reader(
    log_path: Path, obs: Path, navs: Sequence[Path], config: SppConfig, gps_delay_ms: float | None = None
) -> tuple[LogWithFixes, dict[str, object]]:
    """The log's reader with its fixes replaced by SPP fixes from RINEX, and a note for the summary."""
    from gcs_tools.gnss.sources import rinex_input
    from gcs_tools.gnss.timebase import log_time_map
    from gcs_tools.replay.logs import open_log

    data = rinex_input(obs, navs)
    time_map = log_time_map(log_path)
    series = solve_series(data.epochs, config, data.klobuchar)
    fixes = fixes_on_boot_time(series, time_map)
    if not fixes:
        raise UserError(
            f"{obs}: no single-point solution ({int(series.ok.sum())} of {len(series.ok)} epochs)"
        )
    reader = LogWithFixes(open_log(log_path, gps_delay_ms), fixes, f"RINEX {obs.name} -> SPP")
    note = {
        "rinex_obs": str(obs),
        "rinex_nav": [str(p) for p in navs],
        "epochs": len(data.epochs),
        "solutions": int(series.ok.sum()),
        "rejected": dict(data.rejected),
        "time_join": {
            "pairs_used": time_map.pairs_used,
            "pairs_rejected": time_map.rejected,
            "residual_rms_us": time_map.residual_rms_us,
            "drift": time_map.drift,
        },
        "first_fix_boot_s": fixes[0].t_validity_us / 1e6,
        "last_fix_boot_s": fixes[-1].t_validity_us / 1e6,
    }
    return reader, note
