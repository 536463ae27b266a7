"""``beliefnav bench estimator``: speed of the belief-adaptive EKF, in-process and on the real log.

A seeded synthetic flight (200 Hz IMU + attitude, 20 Hz GNSS whose latency is a correlated
process capped at 1.2 s, as in the paper) is built first as wire samples in ARRIVAL order; only
the estimator is timed. Figures:

* ``realtime_factor``: simulated s per wall s, second-order, every sample pushed one by one
  (``Navigator.push``, the SITL/in-process path) and ``estimate()`` called at 50 Hz (ODOMETRY);
* ``realtime_factor_batched``: the same stream with IMU pushed in 0.5 s blocks through
  ``push_imu_batch`` and the fixes that arrived in each block after it (the replay path; the
  final estimate is checked equal to the streaming one);
* ``us_per_imu_sample``: one attitude + one IMU sample pushed, no GNSS;
* ``oosm_cost_ratio``: median cost of fusing a fix 1.2 s late ÷ an on-time fix (constant
  latency, so every fix is fused after the latest one: no re-fusion); the random-latency
  stream's mean cost per fix (re-fusions after out-of-order arrivals included) is reported too;
* ``*_with_velocity``: the streaming factor and the fix costs with the receiver's velocity on
  every fix (fused beside the position with its own gate);
* ``replay_realtime_factor`` and its break-down: ``gcs_tools.bench.replay`` on quad106;
* ``memory_rss_mb_by_sim_min``: resident memory of this process while one Navigator flies a
  one-hour stream (built beforehand, so growth between the marks is the estimator's own), and
  ``memory_growth_mb_10_to_60_min`` (flat over a one-hour flight). Not with --quick.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from typing import Any

import numpy as np
import pymap3d

from companion.domain.geodesy import LocalNedFrame
from companion.domain.physics import STANDARD_GRAVITY_M_S2
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample, Sample
from companion.estimator import Navigator
from companion.estimator.methods import DEFAULT_METHOD
from companion.wiring import navigator_for

IMU_PERIOD_US = 5_000
GNSS_EVERY = 10  # 20 Hz
HOME = LocalNedFrame(-37.8136, 144.9631, 40.0)
METHOD = DEFAULT_METHOD
SEED = 0


def latency_s(rng: np.random.Generator, n: int, period_s: float) -> np.ndarray:
    """Correlated latency (τ 2.5 s, noise 0.03 s, capped at 1.2 s) whose mean alternates 0.3/1.0 s."""
    zeta = math.exp(-period_s / 2.5)
    out = np.empty(n)
    lat = 0.3
    for k in range(n):
        mean = 1.0 if (k * period_s) % 20.0 >= 10.0 else 0.3
        lat = zeta * lat + (1.0 - zeta) * mean + 0.03 * rng.standard_normal()
        lat = min(1.2, max(0.0, lat))
        out[k] = lat
    return out


def flight(duration_s: float, latency: float | None, seed: int = SEED,
           velocity: bool = False) -> list[Sample]:
    """Wire samples in arrival order; ``latency`` None: the correlated process, else constant (s);
    ``velocity``: each fix carries the receiver's velocity (truth + 0.05 m/s noise, no vertical, as
    GPS_RAW_INT gives it)."""
    rng = np.random.default_rng(seed)
    n = int(duration_s * 1e6 / IMU_PERIOD_US)
    t_us = np.arange(n, dtype=np.int64) * IMU_PERIOD_US
    t = t_us * 1e-6
    a_ned = np.stack([0.5 * np.sin(0.4 * t), 0.3 * np.cos(0.25 * t), 0.1 * np.sin(0.7 * t)], axis=1)
    dt = IMU_PERIOD_US * 1e-6
    v = np.vstack([np.zeros(3), np.cumsum(a_ned[:-1] * dt, axis=0)])
    p = np.vstack([np.zeros(3), np.cumsum(v[:-1] * dt, axis=0)]) + [0.0, 0.0, -30.0]
    yaw = 0.5 * t
    q = np.stack([np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)], axis=1)
    f = a_ned - [0.0, 0.0, STANDARD_GRAVITY_M_S2] + 0.02 * rng.standard_normal((n, 3))
    c, s = np.cos(yaw), np.sin(yaw)
    f_frd = np.stack([c * f[:, 0] + s * f[:, 1], -s * f[:, 0] + c * f[:, 1], f[:, 2]], axis=1)
    idx = np.arange(0, n, GNSS_EVERY)
    lat = latency_s(rng, len(idx), GNSS_EVERY * dt) if latency is None else np.full(len(idx), latency)
    z = p[idx] + 0.08 * rng.standard_normal((len(idx), 3))
    events: list[tuple[int, int, Sample]] = []
    for k in range(n):
        events.append((int(t_us[k]), 0, AttitudeSample(int(t_us[k]), q[k])))
        events.append((int(t_us[k]), 1, ImuSample(int(t_us[k]), f_frd[k], np.zeros(3))))
    for j, k in enumerate(idx.tolist()):
        arrival = int(t_us[k]) + int(math.ceil(lat[j] * 1e6 / IMU_PERIOD_US)) * IMU_PERIOD_US
        la, lo, al = HOME.to_geodetic(z[j])
        vel = np.array([*(v[k, 0:2] + 0.05 * rng.standard_normal(2)), np.nan]) if velocity else None
        events.append((arrival, 2, GnssFix(int(t_us[k]), la, lo, al, 3, 12, v_ned_m_s=vel)))
    events.sort(key=lambda e: (e[0], e[1]))
    return [e[2] for e in events]


def streaming_wall_s(samples: list[Sample]) -> tuple[float, float, Navigator]:
    nav = navigator_for(None, METHOD, frame=HOME)
    push, estimate = nav.push, nav.estimate
    imu_count = 0
    t0, c0 = time.perf_counter(), time.process_time()
    for s in samples:
        push(s)
        if type(s) is ImuSample:
            imu_count += 1
            if imu_count % 4 == 0:  # 50 Hz output
                estimate()
    return time.perf_counter() - t0, time.process_time() - c0, nav


def rss_mb() -> float:
    """Resident set size of this process (Linux /proc), MiB."""
    with open("/proc/self/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def memory_over_flight(duration_s: float = 3600.0, every_s: float = 600.0) -> dict[str, Any]:
    """RSS every ``every_s`` of simulated time while a Navigator flies ``duration_s`` (50 Hz estimates)."""
    samples = flight(duration_s, None)
    nav = navigator_for(None, METHOD, frame=HOME)
    marks: dict[str, float] = {}
    imu_count, per_mark = 0, int(every_s * 1e6 / IMU_PERIOD_US)
    for s in samples:
        nav.push(s)
        if type(s) is ImuSample:
            imu_count += 1
            if imu_count % 4 == 0:
                nav.estimate()
            if imu_count % per_mark == 0:
                marks[str(round(imu_count * IMU_PERIOD_US * 1e-6 / 60))] = round(rss_mb(), 2)
    first, last = next(iter(marks.values())), list(marks.values())[-1]
    return {"memory_rss_mb_by_sim_min": marks, "memory_growth_mb_10_to_60_min": round(last - first, 2)}


def batched_wall_s(samples: list[Sample], block_s: float = 0.5) -> tuple[float, float, Navigator]:
    """IMU in blocks through push_imu_batch, then the fixes that arrived within each block."""
    blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray, list[GnssFix]]] = []
    t_l: list[int] = []
    f_l: list[np.ndarray] = []
    q_l: list[np.ndarray] = []
    fixes: list[GnssFix] = []
    q_now = np.array([1.0, 0.0, 0.0, 0.0])  # every IMU sample follows its attitude in flight()
    block_us = int(block_s * 1e6)
    end = block_us
    for s in samples:
        if type(s) is AttitudeSample:
            q_now = s.q_ned_frd
        elif type(s) is ImuSample:
            if s.t_us >= end and t_l:
                blocks.append((np.array(t_l), np.array(f_l), np.array(q_l), fixes))
                t_l, f_l, q_l, fixes = [], [], [], []
                end += block_us
            t_l.append(s.t_us)
            f_l.append(s.acc_frd_m_s2)
            q_l.append(q_now)
        else:
            fixes.append(s)  # type: ignore[arg-type]
    blocks.append((np.array(t_l), np.array(f_l), np.array(q_l), fixes))
    nav = navigator_for(None, METHOD, frame=HOME)
    t0, c0 = time.perf_counter(), time.process_time()
    for t_us, f, q, block_fixes in blocks:
        nav.push_imu_batch(t_us, f, q)
        if block_fixes:  # geodesy for the whole block at once (pymap3d on arrays)
            lat, lon, alt = (np.array([getattr(x, a) for x in block_fixes]) for a in ("lat_deg", "lon_deg",
                                                                                      "alt_m"))
            ned = np.stack(pymap3d.geodetic2ned(lat, lon, alt, HOME.home_lat_deg, HOME.home_lon_deg,
                                                HOME.home_alt_m), axis=1)
            for fix, p_ned_m in zip(block_fixes, ned.tolist(), strict=True):
                nav.push_fix_ned(fix.t_validity_us, p_ned_m)
        nav.estimate()
    return time.perf_counter() - t0, time.process_time() - c0, nav


def fix_costs_us(samples: list[Sample]) -> np.ndarray:
    """Wall µs of each ``push(fix)`` (after the first), everything else untimed."""
    nav = navigator_for(None, METHOD, frame=HOME)
    costs = []
    clock = time.perf_counter
    first = True
    for s in samples:
        if type(s) is GnssFix and not first:
            t0 = clock()
            nav.push(s)
            costs.append(clock() - t0)
        else:
            first = first and type(s) is not GnssFix
            nav.push(s)
    return np.array(costs) * 1e6


def imu_only_us(n: int) -> float:
    nav = navigator_for(None, METHOD, frame=HOME)
    nav.push(AttitudeSample(0, np.array([1.0, 0.0, 0.0, 0.0])))
    nav.push(ImuSample(0, np.array([0.0, 0.0, -9.8]), np.zeros(3)))
    nav.push(GnssFix(0, HOME.home_lat_deg, HOME.home_lon_deg, HOME.home_alt_m, 3, 12))
    rng = np.random.default_rng(SEED)
    att = [AttitudeSample(k * IMU_PERIOD_US, np.array([1.0, 0.0, 0.0, 0.0]) + 0.01 * rng.standard_normal(4))
           for k in range(1, n + 1)]
    imu = [ImuSample(k * IMU_PERIOD_US, np.array([0.0, 0.0, -9.8]) + rng.standard_normal(3), np.zeros(3))
           for k in range(1, n + 1)]
    push = nav.push
    t0 = time.perf_counter()
    for a, i in zip(att, imu, strict=True):
        push(a)
        push(i)
    return (time.perf_counter() - t0) / n * 1e6


def measure(args: argparse.Namespace) -> dict[str, Any]:
    quick = bool(getattr(args, "quick", False))
    duration_s = 20.0 if quick else 120.0
    stream = flight(duration_s, None)
    wall_stream, cpu_stream, nav_s = streaming_wall_s(stream)
    wall_batch, cpu_batch, nav_b = batched_wall_s(stream)
    es, eb = nav_s.estimate(), nav_b.estimate()
    same = es is not None and eb is not None and bool(  # geodesy on arrays vs scalars: ~1e-9 m
        np.allclose(es.p_ned_m, eb.p_ned_m, rtol=0, atol=1e-6) and abs(es.beta - eb.beta) < 1e-6
    )
    on_time = fix_costs_us(flight(duration_s / 2, 0.0))
    late = fix_costs_us(flight(duration_s / 2, 1.2))
    random_latency = fix_costs_us(stream)
    with_velocity = flight(duration_s, None, velocity=True)
    cpu_velocity = streaming_wall_s(with_velocity)[1]
    on_time_v = fix_costs_us(flight(duration_s / 2, 0.0, velocity=True))
    late_v = fix_costs_us(flight(duration_s / 2, 1.2, velocity=True))
    counts = nav_s.counters()
    out: dict[str, Any] = {
        "method": METHOD,
        "sim_duration_s": duration_s,
        "realtime_factor": duration_s / wall_stream,
        "realtime_factor_batched": duration_s / wall_batch,
        # per CPU second of this process: what the code costs when it is not waiting for a core
        "realtime_factor_cpu": duration_s / cpu_stream,
        "realtime_factor_batched_cpu": duration_s / cpu_batch,
        "load_average_1min": os.getloadavg()[0],
        "batched_equals_streaming": same,
        "us_per_imu_sample": imu_only_us(int(200 * min(duration_s, 30.0))),
        "us_per_fix_on_time_median": float(np.median(on_time)),
        "us_per_fix_late_1p2s_median": float(np.median(late)),
        "oosm_cost_ratio": float(np.median(late) / np.median(on_time)),
        "us_per_fix_random_latency_mean": float(np.mean(random_latency)),
        # the same with the receiver's velocity on every fix (fused beside the position)
        "realtime_factor_cpu_with_velocity": duration_s / cpu_velocity,
        "us_per_fix_on_time_median_with_velocity": float(np.median(on_time_v)),
        "oosm_cost_ratio_with_velocity": float(np.median(late_v) / np.median(on_time_v)),
        "gnss_fused": counts["gnss_fused"],
        "gnss_out_of_order": counts["gnss_out_of_order"],
        "gnss_refused": counts["gnss_refused"],
        "gnss_rejected": sum(v for k, v in counts.items() if k.startswith("gnss_rejected")),
        "final_beta": es.beta if es is not None else None,
    }
    if not quick:
        out.update(memory_over_flight())
    try:
        from gcs_tools.bench.replay import REAL_LOG, measure_replay
    except ImportError:  # the replay engine is not in this build
        out["replay_realtime_factor"] = None
    else:
        out.update(measure_replay(REAL_LOG, METHOD))
    return out
