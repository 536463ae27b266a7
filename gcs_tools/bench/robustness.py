"""``beliefnav bench robustness --json``: the estimator on a real log with injected glitches, slow
receivers and an urban-like receiver that reports no accuracy.

The log is tests/data/quad106.tlog (a real hand-flown quadrotor: PX4 FMU IMU and attitude at
~50 Hz, a 5 Hz receiver with ground speed and course, no reported accuracy), 140 s of it from log
time 200 s while it manoeuvres. Every case is replayed with and without the receiver's velocity.

* ``glitch``: faults injected from 60 s into the window (``inject``): GNSS position jumps of
  10-200 m held 3-80 s, a jump fading back to zero (a fading reflection), a heading jump of the
  autopilot's attitude (30°, 90°, 180°; a compass/AHRS fault) alone or with a coincident 100 m
  jump. Each case is scored by its deviation from the GNSS-consistent track (``deviation``): at
  every fix's arrival, the horizontal distance of the estimate right after it to the nearer of
  the clean track and the track the receiver says (the clean one shifted by the glitch of the fix
  just received), so following the glitch and ignoring it both count as consistent and only an
  estimate that is neither (flying away) scores. ``ok``: its maximum is at most that of the same
  method with both innovation gates off (``gnss_gate_sigma`` = ``gnss_vel_gate_sigma`` = 1000),
  or of the same replay without the fault (the clean log's own spread), plus 0.1 m (a tie), and
  no reset follows another within 10 s.
* ``receivers``: the clean window at 5 Hz and decimated to 1 Hz, with no accuracy, and an
  urban-like receiver (a Gauss-Markov error of 8 m per axis with 10 s correlation
  plus 3 m white noise added to every fix, no accuracy): fixes rejected by the gate, resets, and
  the distance to the clean fixes against the raw fixes' own (median, p95, max; the raw fixes
  scored at the estimate's time from their validity: latency counted). ``ok``: no reset storm
  (at most one reset), under half the fixes rejected, and the p95 and max no worse than the raw
  fixes'.

``--quick``: naive and second-order only.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, GnssFix
from companion.estimator import EstimatorConfig, Navigator
from companion.mavlink import codec
from companion.mavlink.tlog import read_tlog

REAL_LOG = Path(__file__).resolve().parents[2] / "tests" / "data" / "quad106.tlog"
WINDOW_S = (200.0, 340.0)
T0_S = 60.0  # glitch start, s into the window
METHODS = ("naive", "adaptive", "vbakf", "second-order")
QUICK_METHODS = ("naive", "second-order")
GATE_OFF = EstimatorConfig(gnss_gate_sigma=1000.0, gnss_vel_gate_sigma=1000.0)
RESET_GAP_S = 10.0
TIE_M = 0.1  # deviations this close to the bar are ties (the clean replay's own spread is ~1 m)
DIAGONAL = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)


@dataclasses.dataclass(frozen=True)
class Glitch:
    """A fault from ``T0_S``: the fixes valid in [T0, T0 + duration) move by ``jump_m`` (north-east
    diagonal), faded linearly to zero over ``fade_s`` when > 0; the attitude turns by ``heading_deg``
    about the vertical for ``heading_s`` (0: for the glitch's duration)."""

    name: str
    jump_m: float = 0.0
    duration_s: float = 0.0
    heading_deg: float = 0.0
    heading_s: float = 0.0
    fade_s: float = 0.0

    def offset_m(self, t_s: float) -> float:
        """The jump in force at ``t_s`` after T0 (m)."""
        if not 0.0 <= t_s < self.duration_s:
            return 0.0
        return self.jump_m * (max(0.0, 1.0 - t_s / self.fade_s) if self.fade_s > 0 else 1.0)


GLITCHES = (
    Glitch("jump 10 m, 8 s", 10.0, 8.0),
    Glitch("jump 30 m, 60 s", 30.0, 60.0),
    Glitch("jump 100 m, 3 s", 100.0, 3.0),
    Glitch("jump 100 m, 8 s", 100.0, 8.0),
    Glitch("jump 100 m, 20 s", 100.0, 20.0),
    Glitch("jump 100 m, held", 100.0, 80.0),
    Glitch("jump 200 m, 3 s", 200.0, 3.0),
    Glitch("jump 100 m fading over 20 s", 100.0, 20.0, fade_s=20.0),
    Glitch("jump 30 m fading over 10 s", 30.0, 10.0, fade_s=10.0),
    Glitch("heading 30°", heading_deg=30.0, heading_s=30.0),
    Glitch("heading 90°", heading_deg=90.0, heading_s=30.0),
    Glitch("heading 180°", heading_deg=180.0, heading_s=30.0),
    Glitch("jump 100 m, 8 s + heading 90°", 100.0, 8.0, heading_deg=90.0),
    Glitch("jump 100 m, 8 s + heading 180°", 100.0, 8.0, heading_deg=180.0),
    Glitch("jump 100 m, held + heading 180°", 100.0, 80.0, heading_deg=180.0),
)


@dataclasses.dataclass(frozen=True)
class Log:
    samples: tuple[Any, ...]  # ImuSample | AttitudeSample | GnssFix, arrival order
    frame: LocalNedFrame  # home = the first 3-D fix of the whole log

    @property
    def t0_us(self) -> int:
        return _t_us(self.samples[0])


def _t_us(s: Any) -> int:
    return int(s.t_validity_us if type(s) is GnssFix else s.t_us)


def load(path: Path = REAL_LOG, window_s: tuple[float, float] | None = WINDOW_S) -> Log:
    """The log's IMU, attitude and GNSS samples (decoded as ``beliefnav replay`` does), in [t0, t1)
    s after its first sample."""
    samples = [s for _, m in read_tlog(path, ("HIGHRES_IMU", "ATTITUDE_QUATERNION", "GPS_RAW_INT"))
               if (s := codec.decode_sample(m)) is not None]
    first = next(s for s in samples if type(s) is GnssFix and s.fix_type >= 3)
    frame = LocalNedFrame(first.lat_deg, first.lon_deg, first.alt_m)
    if window_s is not None:
        t_first = _t_us(samples[0])
        samples = [s for s in samples if window_s[0] * 1e6 <= _t_us(s) - t_first < window_s[1] * 1e6]
    return Log(tuple(samples), frame)


def _yaw_q(psi_rad: float) -> np.ndarray:
    return np.array([math.cos(psi_rad / 2.0), 0.0, 0.0, math.sin(psi_rad / 2.0)])


def _q_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def edit_fixes(log: Log, edit: Callable[[GnssFix, np.ndarray], GnssFix | None]) -> Log:
    """The log with every fix replaced by ``edit(fix, its NED position)`` (None: dropped)."""
    out: list[Any] = []
    for s in log.samples:
        if type(s) is GnssFix:
            s = edit(s, np.asarray(log.frame.to_ned_m(s.lat_deg, s.lon_deg, s.alt_m), dtype=float))
            if s is None:
                continue
        out.append(s)
    return Log(tuple(out), log.frame)


def moved(log: Log, fix: GnssFix, p_ned_m: np.ndarray) -> GnssFix:
    lat, lon, alt = log.frame.to_geodetic(p_ned_m)
    return dataclasses.replace(fix, lat_deg=float(lat), lon_deg=float(lon), alt_m=float(alt))


def inject(log: Log, g: Glitch, velocity: bool = True) -> Log:
    """``log`` with the glitch ``g`` from ``T0_S`` (and without the receiver's velocity unless
    ``velocity``)."""
    t_first = log.t0_us

    def edit(fix: GnssFix, p: np.ndarray) -> GnssFix:
        if not velocity:
            fix = dataclasses.replace(fix, v_ned_m_s=None)
        jump = g.offset_m((fix.t_validity_us - t_first) * 1e-6 - T0_S)
        return moved(log, fix, p + jump * DIAGONAL) if jump else fix

    out = edit_fixes(log, edit)
    if not g.heading_deg:
        return out
    turn, heading_s = _yaw_q(math.radians(g.heading_deg)), g.heading_s or g.duration_s
    samples = [AttitudeSample(s.t_us, _q_mul(turn, s.q_ned_frd))
               if type(s) is AttitudeSample and 0.0 <= (s.t_us - t_first) * 1e-6 - T0_S < heading_s else s
               for s in out.samples]
    return Log(tuple(samples), log.frame)


@dataclasses.dataclass(frozen=True)
class Replay:
    t_s: np.ndarray  # estimate times (s after the log's first sample), one per fix arrival
    p_ned_m: np.ndarray  # (n, 3) the estimate right after that fix
    fix_t_s: np.ndarray  # (n,) validity time of that fix (s after the log's first sample)
    pos_valid: np.ndarray  # (n,) the estimate's validity flag
    resets_t_s: list[float]  # when the reset counter moved
    counters: dict[str, int]
    wall_s: float


def replay(log: Log, method: str, cfg: EstimatorConfig | None = None) -> Replay:
    """The log through a Navigator; the estimate right after each fix's arrival."""
    nav = Navigator(cfg or EstimatorConfig(), method, log.frame)
    t_first = log.t0_us
    t, p, tf, valid, resets = [], [], [], [], []
    n_reset = 0
    t0 = time.perf_counter()
    for s in log.samples:
        nav.push(s)
        if type(s) is GnssFix:
            e = nav.estimate()
            if e is None:
                continue
            t.append((e.t_us - t_first) * 1e-6)
            p.append(e.p_ned_m)
            tf.append((s.t_validity_us - t_first) * 1e-6)
            valid.append(e.pos_valid)
            if e.gnss_resets != n_reset:
                resets.append(t[-1])
                n_reset = e.gnss_resets
    return Replay(np.array(t), np.array(p), np.array(tf), np.array(valid), resets, nav.counters(),
                  time.perf_counter() - t0)


def clean_track(log: Log) -> tuple[np.ndarray, np.ndarray]:
    """(validity times s after the log's first sample, NED positions (n, 3)) of the log's fixes."""
    fixes = [s for s in log.samples if type(s) is GnssFix]
    t = np.array([(f.t_validity_us - log.t0_us) * 1e-6 for f in fixes])
    return t, np.array([log.frame.to_ned_m(f.lat_deg, f.lon_deg, f.alt_m) for f in fixes], dtype=float)


def deviation(r: Replay, clean: tuple[np.ndarray, np.ndarray], g: Glitch) -> np.ndarray:
    """Horizontal distance of each estimate to the nearer of the clean track at its time and that
    track shifted by the glitch of the fix just received (the track the receiver says)."""
    tc, pc = clean
    c = np.column_stack([np.interp(r.t_s, tc, pc[:, i]) for i in range(2)])
    shift = np.array([g.offset_m(t - T0_S) for t in r.fix_t_s])[:, None] * DIAGONAL[None, :2]
    e = r.p_ned_m[:, :2]
    return np.minimum(np.linalg.norm(e - c, axis=1), np.linalg.norm(e - c - shift, axis=1))


def min_reset_gap_s(resets_t_s: list[float]) -> float | None:
    return float(np.diff(resets_t_s).min()) if len(resets_t_s) > 1 else None


def glitch_case(log: Log, clean: tuple[np.ndarray, np.ndarray], g: Glitch, method: str,
                velocity: bool) -> dict[str, Any]:
    bad = inject(log, g, velocity)
    r, off = replay(bad, method), replay(bad, method, GATE_OFF)
    window = r.t_s >= T0_S - 1.0
    d = deviation(r, clean, g)[window]
    d_off = deviation(off, clean, g)[off.t_s >= T0_S - 1.0]
    plain = replay(inject(log, Glitch("none"), velocity), method)  # the same replay without the fault
    d_clean = deviation(plain, clean, Glitch("none"))[plain.t_s >= T0_S - 1.0]
    bar = max(float(d_off.max()), float(d_clean.max())) + TIE_M
    gap = min_reset_gap_s(r.resets_t_s)
    c = r.counters
    return {
        "glitch": g.name, "velocity": velocity, "method": method,
        "deviation_max_m": float(d.max()), "deviation_p95_m": float(np.percentile(d, 95)),
        "gate_off_deviation_max_m": float(d_off.max()), "no_fault_deviation_max_m": float(d_clean.max()),
        "resets": c["gnss_resets"], "min_reset_gap_s": gap, "offsets": c["gnss_offsets"],
        "offset_returns": c["gnss_offset_returns"], "imu_gnss_disagreements": c["imu_gnss_disagreements"],
        "envelope_violations": c["envelope_violations"],
        "ok": bool(d.max() <= bar and (gap is None or gap >= RESET_GAP_S)),
    }


def decimated(log: Log, every: int) -> Log:
    """Every ``every``-th fix only (a slower receiver)."""
    count = iter(range(10**9))
    return edit_fixes(log, lambda f, p: f if next(count) % every == 0 else None)


def urban_like(log: Log, seed: int = 0, white_scale: float = 1.0) -> Log:
    """Every fix moved by a Gauss-Markov error (8 m per horizontal axis, 4 m vertical, 10 s
    correlation) plus white noise (3 m, 2 m) × ``white_scale``, no accuracy reported: a single-point
    receiver in a street canyon (errors of 5-50 m) that states nothing about them. The random draws
    do not depend on ``white_scale``: 0 gives the same seed's correlated error alone."""
    rng = np.random.default_rng(seed)
    sigma_b, sigma_w = np.array([8.0, 8.0, 4.0]), np.array([3.0, 3.0, 2.0]) * white_scale
    bias = [rng.standard_normal(3) * sigma_b]
    last_s: list[float] = []

    def edit(fix: GnssFix, p: np.ndarray) -> GnssFix:
        t = fix.t_validity_us * 1e-6
        if last_s:
            k = math.exp(-(t - last_s[0]) / 10.0)
            bias[0] = k * bias[0] + math.sqrt(1 - k * k) * rng.standard_normal(3) * sigma_b
        last_s[:] = [t]
        return moved(log, fix, p + bias[0] + rng.standard_normal(3) * sigma_w)

    return edit_fixes(log, edit)


def without_velocity(log: Log) -> Log:
    return edit_fixes(log, lambda f, p: dataclasses.replace(f, v_ned_m_s=None))


def distances_to_clean(r: Replay, clean: tuple[np.ndarray, np.ndarray],
                       fixes: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(the estimate's, the fixes') horizontal distance to the clean track at each estimate's time:
    ``fixes`` = (validity times, NED positions (n, 3)), each used from its validity to the estimate's
    time (the fix just received: latency counted)."""
    tc, pc = clean
    c = np.column_stack([np.interp(r.t_s, tc, pc[:, i]) for i in range(2)])
    raw_t, raw_p = fixes
    k = np.clip(np.searchsorted(raw_t, r.fix_t_s), 0, len(raw_t) - 1)
    return np.linalg.norm(r.p_ned_m[:, :2] - c, axis=1), np.linalg.norm(raw_p[k, :2] - c, axis=1)


def receiver_case(log: Log, clean: tuple[np.ndarray, np.ndarray], name: str, method: str,
                  velocity: bool) -> dict[str, Any]:
    received = log if velocity else without_velocity(log)
    r = replay(received, method)
    est, raw = distances_to_clean(r, clean, clean_track(received))
    cnt = r.counters
    tested = cnt["gnss_fused"] + cnt["gnss_rejected_innovation"]
    rejected = cnt["gnss_rejected_innovation"] / max(1, tested)
    stats = {q: float(f(est)) for q, f in (("median", np.median), ("p95", lambda a: np.percentile(a, 95)),
                                           ("max", np.max))}
    raw_stats = {q: float(f(raw)) for q, f in (("median", np.median), ("p95", lambda a: np.percentile(a, 95)),
                                               ("max", np.max))}
    return {
        "receiver": name, "velocity": velocity, "method": method, "fixes": tested,
        "rejected_fraction": rejected, "resets": cnt["gnss_resets"], "offsets": cnt["gnss_offsets"],
        "distance_to_clean_m": stats, "raw_fixes_distance_to_clean_m": raw_stats,
        "ok": bool(cnt["gnss_resets"] <= 1 and rejected < 0.5 and stats["p95"] <= raw_stats["p95"] + 1e-9
                   and stats["max"] <= raw_stats["max"] + 1e-9),
    }


def receivers(log: Log) -> dict[str, Log]:
    urban = urban_like(log)
    return {"5 Hz, no accuracy": log, "1 Hz, no accuracy": decimated(log, 5),
            "urban-like 5 Hz, no accuracy": urban, "urban-like 1 Hz, no accuracy": decimated(urban, 5)}


def measure(args: argparse.Namespace) -> dict[str, Any]:
    methods = QUICK_METHODS if getattr(args, "quick", False) else METHODS
    t0 = time.perf_counter()
    log = load()
    clean = clean_track(log)
    glitch = [glitch_case(log, clean, g, m, v) for g in GLITCHES for v in (True, False) for m in methods]
    rx = [receiver_case(received, clean, name, m, v)
          for name, received in receivers(log).items() for v in (True, False) for m in methods]
    return {
        "log": f"{REAL_LOG.name}, {WINDOW_S[0]:.0f}-{WINDOW_S[1]:.0f} s",
        "methods": list(methods),
        "glitch_ok": sum(c["ok"] for c in glitch), "glitch_cases": len(glitch),
        "glitch_worst_excess_over_gate_off_m": max(c["deviation_max_m"] - c["gate_off_deviation_max_m"]
                                                   for c in glitch),
        "glitch_resets_within_10_s": sum(1 for c in glitch if c["min_reset_gap_s"] is not None
                                         and c["min_reset_gap_s"] < RESET_GAP_S),
        "receivers_ok": sum(c["ok"] for c in rx), "receiver_cases": len(rx),
        "wall_s": time.perf_counter() - t0,
        "glitch": glitch, "receivers": rx,
    }
