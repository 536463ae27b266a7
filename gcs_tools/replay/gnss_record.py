"""What the estimator did with each GNSS input of a replay: ``gnss_fixes.csv`` (a fix: fused, reset to, held
as a step or rejected, and why) and ``gnss_epochs.csv`` (a raw epoch of the tightly coupled filter: its
satellites used and excluded, their mean belief, a reset).

Kept by the replay, not by the estimator: the decision is read, right after the navigator took the input,
from its counters (a fix refused before the gate: ``gnss_rejected_<reason>``) and from the fusion entry
the engine made for it (``companion.estimator.engine.Fusion``: the gate's ratio, NIS, glitch flag and the
cumulative rejections / resets / returns against the entry before it; ``companion.tight.engine.Entry``:
the epoch's ``EpochInfo`` and reset count). A fix valid after the newest IMU sample waits in the engine
for the IMU (``future_tolerance_s``); it is decided when an IMU sample reaches its time. The decision
recorded is the one made when the input was inserted: a later out-of-order fix that re-fuses it
(``gnss_refused``) does not rewrite its row.

Rows are streamed to the CSV files (``out_dir``) or kept in memory (``arrays``); each file is written
only when the replay had such inputs.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from time import perf_counter
from typing import IO, Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix
from companion.errors import UserError

FIX_FILE = "gnss_fixes.csv"
EPOCH_FILE = "gnss_epochs.csv"
FIX_COLUMNS = ("t_s", "lat_deg", "lon_deg", "alt_m", "p_n_m", "p_e_m", "p_d_m", "segment", "accepted",
               "reason", "test_ratio", "nis")
EPOCH_COLUMNS = ("t_s", "segment", "n_sats", "n_used", "n_excluded", "n_low_belief", "beta_mean", "nis",
                 "reset", "reason")
# a fix's reason -> accepted (its position fused as measured, or the state reset onto it)
ACCEPTED = {"start": 1, "fused": 1, "reset": 1, "return": 1}
# rejected by the gate, or held relative to an open GNSS step (its own position not fused)
GATED = ("innovation", "step")
LOW_BELIEF = 0.5  # a used satellite whose belief is below this is counted as down-weighted
FLUSH_ROWS = 256


def _changed(before: dict[str, int], after: dict[str, int]) -> str | None:
    """The counter of a refusal before the gate that moved (``gnss_rejected_X`` -> ``X``; the tight
    navigator's ``gnss_fix_ignored`` -> ``fix_ignored``), else None."""
    for key, n in after.items():
        if n != before.get(key, 0) and key != "gnss_rejected_innovation" and (
                key.startswith("gnss_rejected_") or key == "gnss_fix_ignored"):
            return key.removeprefix("gnss_rejected_").removeprefix("gnss_")
    return None


class GnssRecord:
    """Per-input decisions of one replay (all segments): ``pushed`` instead of ``nav.push`` for a GNSS
    input, ``imu`` after each IMU sample is pushed, ``end_segment`` before a navigator is replaced."""

    def __init__(self, frame: LocalNedFrame, out_dir: Path | None) -> None:
        self.frame, self.out_dir = frame, out_dir
        self.segment = 0
        # decided, not yet written: [t_us, lat, lon, alt, segment, reason, test ratio, nis]
        self._fixes: list[list[Any]] = []
        self._epochs: list[list[Any]] = []
        self._waiting: list[tuple[int, Any, dict[str, int], Any]] = []  # (t_us, sample, counters, nav)
        self._files: dict[str, tuple[IO[str], Any]] = {}
        self._memory: dict[str, list[list[Any]]] = {FIX_FILE: [], EPOCH_FILE: []}
        self.wait_until_us = 1 << 62  # the next waiting input's time (the IMU loop's one comparison)
        self.overhead_s = 0.0  # spent recording, not estimating (left out of the summary's estimator time)

    # ------------------------------------------------------------------ input
    def pushed(self, sample: Any, nav: Any) -> None:
        """Push ``sample`` (a GnssFix or a raw epoch) into ``nav`` and record what it did."""
        t0 = perf_counter()
        before = nav.counters()
        t1 = perf_counter()
        nav.push(sample)
        t2 = perf_counter()
        try:
            self._pushed(sample, nav, before)
        finally:
            self.overhead_s += t1 - t0 + perf_counter() - t2

    def _pushed(self, sample: Any, nav: Any, before: dict[str, int]) -> None:
        after = nav.counters()
        t_us = sample.t_validity_us if type(sample) is GnssFix else sample.t_us
        reason = _changed(before, after)
        if reason is not None:
            self._decided(sample, t_us, reason, None, None)
            return
        entry = _entry(nav, t_us, type(sample) is GnssFix)
        if entry is not None:
            self._decided(sample, t_us, None, *entry)
            return
        engine = getattr(nav, "engine", None)
        if engine is not None and len(engine.imu) and t_us > engine.imu.last_t_us:  # waits for the IMU
            self._waiting.append((t_us, sample, before, nav))
            self.wait_until_us = min(self.wait_until_us, t_us)
            return
        self._decided(sample, t_us, _by_counters(before, after), None, None)

    def imu(self, t_us: int) -> None:
        """An IMU sample at ``t_us`` was pushed: decide the inputs that waited for it."""
        if t_us >= self.wait_until_us:
            t0 = perf_counter()
            self._resolve(lambda w: w[0] <= t_us)
            self.overhead_s += perf_counter() - t0

    def _resolve(self, due: Any) -> None:
        keep = []
        for w in self._waiting:
            if not due(w):
                keep.append(w)
                continue
            t_us, sample, before, nav = w
            entry = _entry(nav, t_us, type(sample) is GnssFix)
            if entry is not None:
                self._decided(sample, t_us, None, *entry)
            else:
                after = nav.counters()
                too_old = after.get("gnss_rejected_too_old", 0) > before.get("gnss_rejected_too_old", 0)
                self._decided(sample, t_us, "too_old" if too_old else "unresolved", None, None)
        self._waiting = keep
        self.wait_until_us = min((w[0] for w in keep), default=1 << 62)

    def end_segment(self) -> None:
        """The navigator is about to be replaced (a log restart) or the replay ends."""
        self._resolve(lambda w: True)
        self.flush()

    def restart(self) -> None:
        self.end_segment()
        self.segment += 1

    # ------------------------------------------------------------------ rows
    def _decided(self, sample: Any, t_us: int, reason: str | None, entry: Any, prev: Any) -> None:
        if type(sample) is GnssFix:
            ratio = nis = math.nan
            if reason is None:
                reason, ratio, nis = _fix_reason(entry, prev)
            self._fixes.append([t_us, sample.lat_deg, sample.lon_deg, sample.alt_m, self.segment, reason,
                                ratio, nis])
            if len(self._fixes) >= FLUSH_ROWS:
                self.flush()
            return
        if reason is not None:  # refused before the filter
            self._epochs.append([t_us / 1e6, self.segment, sample.epoch.n, 0, 0, 0, math.nan, math.nan, 0,
                                 reason])
        else:
            info = entry.info
            n_tested = 0 if info.y_m is None else len(info.y_m)
            low = 0 if info.used is None else int(np.count_nonzero(info.used & (info.beta < LOW_BELIEF)))
            reset = int(prev is not None and entry.totals[2] > prev.totals[2])
            n_sats = info.n_sats if prev is not None else sample.epoch.n  # the start: the epoch's own SPP
            self._epochs.append([t_us / 1e6, self.segment, n_sats, info.n_used, n_tested - info.n_used,
                                 low, info.beta_mean, info.nis, reset,
                                 "start" if prev is None else "reset" if reset else
                                 "fused" if info.n_used else "no_satellite_used"])

    def flush(self) -> None:
        if self._fixes:
            rows, self._fixes = self._fixes, []
            lla = np.array([r[1:4] for r in rows], dtype=float)
            with np.errstate(invalid="ignore"):
                ned = np.asarray(self.frame.to_ned_m(lla[:, 0], lla[:, 1], lla[:, 2]), dtype=float).T
            out = [[r[0] / 1e6, *r[1:4], *p, r[4], ACCEPTED.get(r[5], 0), r[5], r[6], r[7]]
                   for r, p in zip(rows, ned.reshape(len(rows), 3), strict=True)]
            self._write(FIX_FILE, FIX_COLUMNS, out)
        if self._epochs:
            rows, self._epochs = self._epochs, []
            self._write(EPOCH_FILE, EPOCH_COLUMNS, rows)

    def _write(self, name: str, columns: tuple[str, ...], rows: list[list[Any]]) -> None:
        if self.out_dir is None:
            self._memory[name].extend(rows)
            return
        f = self._files.get(name)
        if f is None:
            try:
                self.out_dir.mkdir(parents=True, exist_ok=True)
                fh = (self.out_dir / name).open("w", newline="", encoding="utf-8")
            except OSError as exc:
                raise UserError(f"--out {self.out_dir}: cannot write {name}: {exc.strerror or exc}") from None
            f = self._files[name] = (fh, csv.writer(fh))
            f[1].writerow(columns)
        f[1].writerows([[_text(v) for v in row] for row in rows])

    def close(self) -> None:
        """The replay ended: the inputs still waiting decided, every row written, the files closed; a
        record file this replay did not write (a previous run's in the same ``out_dir``) removed, so
        that neither the figures nor the printed file list take it for this run's."""
        self.end_segment()
        written = set(self._files)
        self.abandon()
        if self.out_dir is not None:
            for name in (FIX_FILE, EPOCH_FILE):
                if name not in written:
                    (self.out_dir / name).unlink(missing_ok=True)

    def abandon(self) -> None:
        """Close the files (after ``close``, or when the replay failed: what is not written is dropped)."""
        for fh, _ in self._files.values():
            fh.close()
        self._files.clear()

    def arrays(self) -> dict[str, dict[str, np.ndarray]]:
        """The rows kept in memory (no ``out_dir``): file name -> columns (empty when none)."""
        out = {}
        for name, columns in ((FIX_FILE, FIX_COLUMNS), (EPOCH_FILE, EPOCH_COLUMNS)):
            rows = self._memory[name]
            if rows:
                out[name] = _columns(columns, [[_text(v) for v in r] for r in rows])
        return out


def _text(v: Any) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return "" if not math.isfinite(v) else f"{float(v):.9g}"


def _columns(columns: tuple[str, ...], rows: list[list[str]]) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for k, name in enumerate(columns):
        values = [r[k] for r in rows]
        if name == "reason":
            out[name] = np.array(values, dtype=str)
        else:
            out[name] = np.array([float(v) if v else math.nan for v in values], dtype=float)
    return out


def read(path: Path) -> dict[str, np.ndarray]:
    """``gnss_fixes.csv`` or ``gnss_epochs.csv`` -> columns (``reason`` as str, the rest float; empty:
    NaN)."""
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    return _columns(tuple(rows[0]), rows[1:])


def _entry(nav: Any, t_us: int, fix: bool) -> tuple[Any, Any] | None:
    """The engine's entry for the input valid at ``t_us`` and the entry before it (None: the first), or
    None when the engine holds none (not yet inserted, refused, or a navigator without an engine)."""
    entries = getattr(getattr(nav, "engine", None), "entries", None)
    if not entries:
        return None
    for i in range(len(entries) - 1, -1, -1):
        e = entries[i]
        if e.t_us < t_us:
            return None
        if e.t_us == t_us and (getattr(e, "z_ned_m", None) is not None if fix  # a fix's fusion
                               else hasattr(getattr(e, "meas", None), "z_m")  # an epoch's
                               or (i == 0 and len(entries) == 1)):  # the tight filter's start: an anchor
            return e, entries[i - 1] if i > 0 else None
    return None


def _fix_reason(e: Any, prev: Any) -> tuple[str, float, float]:
    """(reason, the gate's test ratio, NIS) of a fix's fusion entry ``e`` after ``prev``."""
    ratio, nis = float(e.test_ratio), float(e.nis)
    if prev is None:
        return "start", ratio, nis
    if e.n_resets > prev.n_resets:
        return "reset", ratio, nis
    if e.n_rejected > prev.n_rejected:
        return "innovation", ratio, nis
    if e.n_returns > prev.n_returns:
        return "return", ratio, nis
    return ("step" if e.glitch else "fused"), ratio, nis


def _by_counters(before: dict[str, int], after: dict[str, int]) -> str:
    """A navigator without an engine's entries: fused or rejected by the gate, from its counters."""
    if after.get("gnss_rejected_innovation", 0) > before.get("gnss_rejected_innovation", 0):
        return "innovation"
    if after.get("gnss_fused", 0) > before.get("gnss_fused", 0):
        return "fused"
    return "unresolved"
