"""``beliefnav bench telemetry``: fan-out of the estimator's topics to 10 subscriber processes.

Two measurements, both over real Zenoh on 127.0.0.1 with a private hub port:

1. Fan-out at the default rates (estimate 50 Hz, belief 20 Hz, health 5 Hz) in real time to
   ``N_SUBSCRIBERS`` processes that decode every message: delivered rate, end-to-end latency
   (publish call -> decoded in the subscriber; both clocks are this host's), drops.
2. The estimator (``Navigator``, second-order) run as fast as possible over a pre-generated
   SimVehicle flight, publishing its topics at the default rates in wall time, with the 10
   subscribers attached versus none: ``realtime_factor`` = simulated s / wall s, median of runs.
   The ``stress_sim_rate_*`` figures publish at the SIMULATED rates instead (hundreds of times the
   default rate): there the 10 subscriber processes decoding everything share the host's cores
   with the estimator, so they measure the machine more than the publisher.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from typing import Any

import numpy as np

from companion.wire import zenoh_codec as zc
from companion.wire.telemetry import TelemetryConfig, TelemetryPublisher

N_SUBSCRIBERS = 10
RATES_HZ = {"estimate": 50, "belief": 20, "health": 5}  # the estimator node's publishing rates
IMU_HZ = 200
FANOUT_VEHICLE, RTF_VEHICLE = "fanout", "rtf"  # separate keys for the two phases


def subscriber_main() -> None:
    """Child process: decode everything, print counts and latencies (JSON) on SIGTERM."""
    from companion.wire.telemetry import TelemetrySubscriber

    counts: Counter[str] = Counter()
    latency_ms: list[float] = []
    lock = threading.Lock()

    def on(msg: Any) -> None:
        with lock:
            counts[msg.vehicle] += 1
            if msg.vehicle == FANOUT_VEHICLE and msg.sent_unix_ns is not None:
                latency_ms.append((msg.recv_unix_ns - msg.sent_unix_ns) * 1e-6)

    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    with TelemetrySubscriber(on, key_expr="beliefnav/**") as sub:
        print("ready", flush=True)
        done.wait()
        with lock:
            out = {"counts": dict(counts), "latency_ms": latency_ms, "malformed": sub.malformed_total}
    print(json.dumps(out), flush=True)


def _start_subscribers(n: int, env: dict[str, str]) -> list[subprocess.Popen]:
    code = "from gcs_tools.bench.telemetry import subscriber_main; subscriber_main()"
    procs = []
    for _ in range(n):
        procs.append(subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE,
                                      text=True))
        assert procs[-1].stdout is not None
        if procs[-1].stdout.readline().strip() != "ready":  # the first one becomes the hub
            raise RuntimeError("subscriber failed to start")
    return procs


def _stop_subscribers(procs: list[subprocess.Popen]) -> list[dict[str, Any]]:
    results = []
    for p in procs:
        p.send_signal(signal.SIGTERM)
    for p in procs:
        try:
            out, _ = p.communicate(timeout=20)
            results.append(json.loads(out.strip().splitlines()[-1]))
        except (subprocess.TimeoutExpired, ValueError, IndexError):
            p.kill()
            p.communicate()
            results.append({"counts": {}, "latency_ms": [], "malformed": 0})
    return results


def _estimator_messages(est: Any, counters: dict[str, int], k_imu: int) -> list[tuple[str, Any]]:
    """What the estimator node publishes after its ``k_imu``-th IMU sample."""
    out: list[tuple[str, Any]] = []
    if k_imu % (IMU_HZ // RATES_HZ["estimate"]) == 0:
        out.append(("estimate", est))
    if k_imu % (IMU_HZ // RATES_HZ["belief"]) == 0:
        out.append(("belief", zc.Belief.of(est)))
    if k_imu % (IMU_HZ // RATES_HZ["health"]) == 0:
        out.append(("health", zc.Health(est.t_us, counters)))
    return out


def fan_out(duration_s: float, cfg: TelemetryConfig, flight: list[Any]) -> dict[str, Any]:
    """Real-time publishing at the default rates (replaying estimates of the pre-flown flight)."""
    ests = flight
    sent: Counter[str] = Counter()
    with TelemetryPublisher(FANOUT_VEHICLE, "companion", cfg) as pub:
        for topic in RATES_HZ:
            pub.wait_for_subscribers(topic)
        deadline = time.monotonic() + 15.0  # gossip links the publisher to every subscriber
        while pub.peer_count() < N_SUBSCRIBERS and time.monotonic() < deadline:
            time.sleep(0.05)
        peers = pub.peer_count()
        t0 = time.monotonic()
        k = 0
        while (now := time.monotonic() - t0) < duration_s:
            est, counters = ests[k // 4 % len(ests)]
            for topic, obj in _estimator_messages(est, counters, k):
                pub.publish(topic, obj)
                sent[topic] += 1
            k += 1
            time.sleep(max(0.0, k / IMU_HZ - now))
        wall_s = time.monotonic() - t0
        pub.flush()
        time.sleep(0.5)
        pub_counters = pub.counters()
    return {"sent": dict(sent), "publisher": pub_counters, "wall_s": wall_s, "peers": peers}


def fly_samples(duration_s: float, seed: int) -> list[Any]:
    """Estimator inputs (arrival order) of a SimVehicle hover flight on the test city."""
    from companion.mission import load_mission
    from simvehicle import SimVehicle

    mission = load_mission("test")
    sim = SimVehicle(mission, 0, seed)
    samples: list[Any] = []
    for _ in range(int(duration_s / 0.05)):
        out = sim.advance(None, None)
        samples += sorted([*out.imu, *out.attitude], key=lambda s: s.t_us) + list(out.gnss)
    return samples


def run_estimator(samples: list[Any], pub: TelemetryPublisher | None,
                  wall_rate: bool = True) -> tuple[float, list[Any]]:
    """(wall s, [(estimate, counters)] at 50 Hz) running the estimator as fast as possible.

    ``wall_rate``: publish each topic at its default rate in WALL time (what a node does at real
    time; faster than that it keeps the latest); otherwise at the simulated rate (a stress test).
    """
    from companion.estimator import Navigator
    from companion.wire.samples import ImuSample

    nav = Navigator(method="second-order")
    k = 0
    kept: list[Any] = []
    next_s = dict.fromkeys(RATES_HZ, 0.0)
    t0 = time.perf_counter()
    for s in samples:
        nav.push(s)
        if isinstance(s, ImuSample):
            k += 1
            est = nav.estimate()
            if est is None:
                continue
            if pub is not None:
                for topic, obj in _estimator_messages(est, nav.counters(), k):
                    if wall_rate:
                        now = time.perf_counter()
                        if now < next_s[topic]:
                            continue
                        next_s[topic] = now + 1.0 / RATES_HZ[topic]
                    pub.publish(topic, obj)
            elif k % 4 == 0:
                kept.append((est, nav.counters()))
    return time.perf_counter() - t0, kept


def measure(args: argparse.Namespace) -> dict[str, Any]:
    quick = bool(getattr(args, "quick", False))
    fan_s, flight_s, repeats = (3.0, 10.0, 3) if quick else (10.0, 30.0, 5)
    port = _free_port()
    env = {**os.environ, "BELIEFNAV_ZENOH_HUB": f"tcp/127.0.0.1:{port}"}
    cfg = TelemetryConfig.from_env(env)
    samples = fly_samples(flight_s, seed=0)
    _, flight = run_estimator(samples, None)

    def rtf_runs(pub: TelemetryPublisher, wall_rate: bool = True) -> list[float]:
        return [flight_s / run_estimator(samples, pub, wall_rate)[0] for _ in range(repeats)]

    rtf_bare = [flight_s / run_estimator(samples, None)[0] for _ in range(repeats)]
    with TelemetryPublisher(RTF_VEHICLE, "companion", cfg) as pub:  # no subscribers attached
        rtf_none = rtf_runs(pub)
        stress_none = rtf_runs(pub, wall_rate=False)
        pub.flush(10.0)
    procs = _start_subscribers(N_SUBSCRIBERS, env)
    try:
        fan = fan_out(fan_s, cfg, flight)
        with TelemetryPublisher(RTF_VEHICLE, "companion", cfg) as pub:
            pub.wait_for_subscribers("estimate")
            time.sleep(1.0)
            rtf_ten = rtf_runs(pub)
            stress_ten = rtf_runs(pub, wall_rate=False)
            flushed = pub.flush(10.0)
    finally:
        results = _stop_subscribers(procs)
    sent_total = sum(fan["sent"].values())
    lat = np.concatenate([np.asarray(r["latency_ms"], dtype=float) for r in results])
    delivered_fan = [r["counts"].get(FANOUT_VEHICLE, 0) for r in results]
    return {
        "subscribers": N_SUBSCRIBERS,
        "publisher_peers_linked": fan["peers"],
        "rates_hz": RATES_HZ,
        "fanout_duration_s": round(fan["wall_s"], 2),
        "sent_per_subscriber": sent_total,
        "delivered_rate_hz": round(float(np.mean(delivered_fan)) / fan["wall_s"], 1),
        "delivered_fraction": round(float(np.sum(delivered_fan)) / (sent_total * N_SUBSCRIBERS), 5),
        "drops_at_default_rate": int(sent_total * N_SUBSCRIBERS - np.sum(delivered_fan))
        + fan["publisher"]["dropped_queue_full"],
        "latency_p50_ms": round(float(np.percentile(lat, 50)), 3) if len(lat) else None,
        "latency_p99_ms": round(float(np.percentile(lat, 99)), 3) if len(lat) else None,
        "latency_max_ms": round(float(np.max(lat)), 3) if len(lat) else None,
        "malformed": int(sum(r["malformed"] for r in results)),
        "estimator_realtime_factor_no_subscribers": round(float(np.median(rtf_none)), 1),
        "estimator_realtime_factor_10_subscribers": round(float(np.median(rtf_ten)), 1),
        "realtime_factor_ratio": round(float(np.median(rtf_ten) / np.median(rtf_none)), 3),
        "estimator_realtime_factor_without_telemetry": round(float(np.median(rtf_bare)), 1),
        "stress_sim_rate_realtime_factor_no_subscribers": round(float(np.median(stress_none)), 1),
        "stress_sim_rate_realtime_factor_10_subscribers": round(float(np.median(stress_ten)), 1),
        "estimator_flight_s": flight_s,
        "publisher_flushed": flushed,
    }


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
