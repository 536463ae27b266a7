"""``beliefnav bench telemetry``: fan-out of the estimator's topics to 10 subscriber processes.

Two measurements, both over real Zenoh on 127.0.0.1 with a private hub port:

1. Fan-out at the default rates (estimate 50 Hz, belief 20 Hz, health 5 Hz) in real time to
   ``N_SUBSCRIBERS`` processes that decode every message: delivered rate, end-to-end latency
   (publish call -> decoded in the subscriber; both clocks are this host's), drops.
2. The estimator (``Navigator``, second-order) run as fast as possible over a pre-generated
   SimVehicle flight, publishing its topics at the default rates in wall time, with the 10
   subscribers attached versus none: ``realtime_factor`` = simulated s / wall s, median of runs;
   ``realtime_factor_ratio`` = median over alternating pairs of runs (with / without). The
   ``cpu_`` figures divide by this process's CPU time instead (all its threads, Zenoh's included):
   on a busy shared host the wall figures mostly measure the scheduler, the CPU ones the publisher.
   The ``stress_sim_rate_*`` figures publish at the SIMULATED rates instead (hundreds of times the
   default rate): there the 10 subscriber processes decoding everything share the host's cores
   with the estimator, so they measure the machine more than the publisher.

Before each measurement the publisher sends ``setpoint`` warm-up messages until EVERY subscriber
reports (on its stdout) that it receives them: a subscriber process joins the mesh through the hub
and is linked to the publisher directly only once gossip has run, and in peer-to-peer mode the hub
does not forward, so until then it receives nothing. (Zenoh's matching status only tells that
*some* subscriber matches, and a linked peer is not yet a peer whose declarations have arrived:
waiting on either let a late subscriber miss a whole 3 s run.) ``link_wait_s`` is how long that took.
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

from companion.domain.samples import AttitudeSample, ImuSample, Setpoint
from companion.telemetry import codec as zc
from companion.telemetry.pubsub import EstimatorRates, TelemetryConfig, TelemetryPublisher

N_SUBSCRIBERS = 10
RATES_HZ = {topic: 1_000_000 // getattr(EstimatorRates, f"{topic}_period_us")  # the node's publishing rates
            for topic in ("estimate", "belief", "health")}
IMU_HZ = 200
FANOUT_VEHICLE, RTF_VEHICLE = "fanout", "rtf"  # separate keys for the phases
SETTLE_S = 2.0  # after starting 9 processes at once: their imports and mutual gossip links load the host
SINGLE_VEHICLE = "fanout1"  # the same fan-out with ONE subscriber process: the path without fan-out
WARMUP_TOPIC = "setpoint"  # sent until every subscriber receives the publisher; not counted


def subscriber_main() -> None:
    """Child process: decode everything; say "receiving" on the first warm-up message (setpoint) of
    each publisher; on SIGUSR1 (a snapshot) and on SIGTERM print counts, latencies and decode times
    (one JSON line)."""
    from companion.telemetry.pubsub import TelemetrySubscriber

    counts: Counter[str] = Counter()
    latency_ms: dict[str, list[float]] = {FANOUT_VEHICLE: [], SINGLE_VEHICLE: []}
    decode_us: list[float] = []
    warm: set[str] = set()
    lock = threading.Lock()

    def on(msg: Any) -> None:
        with lock:
            if msg.topic == WARMUP_TOPIC:
                if msg.vehicle not in warm:
                    warm.add(msg.vehicle)
                    print("receiving", flush=True)
                return
            counts[msg.vehicle] += 1
            if msg.vehicle in latency_ms and msg.sent_unix_ns is not None:
                latency_ms[msg.vehicle].append((msg.recv_unix_ns - msg.sent_unix_ns) * 1e-6)
                decode_us.append((time.time_ns() - msg.recv_unix_ns) * 1e-3)  # callback entry -> decoded

    done, snapshot = threading.Event(), threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    signal.signal(signal.SIGUSR1, lambda *_: snapshot.set())

    def report() -> None:
        with lock:
            out = {"counts": dict(counts), "latency_ms": latency_ms, "malformed": sub.malformed_total,
                   "decode_us": decode_us}
            print(json.dumps(out), flush=True)

    with TelemetrySubscriber(on, key_expr="beliefnav/**") as sub:
        print("ready", flush=True)
        while not done.wait(0.02):
            if snapshot.is_set():
                snapshot.clear()
                report()
        report()


def _start_subscribers(n: int, env: dict[str, str]) -> list[subprocess.Popen]:
    """``n`` subscriber processes started together (start one first: it becomes the hub)."""
    code = "from gcs_tools.bench.telemetry import subscriber_main; subscriber_main()"
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True)
             for _ in range(n)]
    for p in procs:
        assert p.stdout is not None
        if p.stdout.readline().strip() != "ready":
            raise RuntimeError("subscriber failed to start")
    return procs


def await_receiving(pub: TelemetryPublisher, procs: list[subprocess.Popen], timeout_s: float = 30.0) -> float:
    """Publish warm-up setpoints until every subscriber process receives them; returns the wait in s."""
    said: list[str] = []
    readers = [threading.Thread(target=lambda p=p: said.append(p.stdout.readline().strip()), daemon=True)
               for p in procs]
    for r in readers:
        r.start()
    t0 = time.monotonic()
    k = 0
    sp = Setpoint(0, np.zeros(3), np.zeros(3), np.zeros(3))
    while any(r.is_alive() for r in readers):
        if time.monotonic() - t0 > timeout_s:
            raise RuntimeError(f"only {len(said)} of {len(procs)} subscribers received the publisher "
                               f"within {timeout_s:.0f} s")
        pub.publish(WARMUP_TOPIC, Setpoint(k, sp.p_ned_m, sp.v_ned_m_s, sp.a_ned_m_s2))
        k += 1
        time.sleep(0.01)
    if said != ["receiving"] * len(procs):
        raise RuntimeError(f"subscriber said {said!r}")
    return time.monotonic() - t0


def _snapshot_subscribers(procs: list[subprocess.Popen]) -> list[dict[str, Any]]:
    """What every subscriber has received so far (asked with SIGUSR1, answered on stdout)."""
    for p in procs:
        p.send_signal(signal.SIGUSR1)
    results = []
    for p in procs:
        assert p.stdout is not None
        results.append(json.loads(p.stdout.readline()))
    return results


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
            results.append({"counts": {}, "latency_ms": {}, "malformed": 0, "decode_us": [], "lost": True})
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


def fan_out(duration_s: float, cfg: TelemetryConfig, flight: list[Any],
            procs: list[subprocess.Popen], vehicle: str = FANOUT_VEHICLE) -> dict[str, Any]:
    """Real-time publishing at the default rates (replaying estimates of the pre-flown flight)."""
    ests = flight
    sent: Counter[str] = Counter()
    call_us: list[float] = []
    with TelemetryPublisher(vehicle, "companion", cfg) as pub:
        link_wait_s = await_receiving(pub, procs)
        peers = pub.peer_count()
        t0 = time.monotonic()
        k = 0
        while (now := time.monotonic() - t0) < duration_s:
            est, counters = ests[k // 4 % len(ests)]
            for topic, obj in _estimator_messages(est, counters, k):
                c0 = time.perf_counter_ns()
                pub.publish(topic, obj)
                call_us.append((time.perf_counter_ns() - c0) * 1e-3)
                sent[topic] += 1
            k += 1
            time.sleep(max(0.0, k / IMU_HZ - now))
        wall_s = time.monotonic() - t0
        time.sleep(0.5)
        pub_counters = pub.counters()
    return {"sent": dict(sent), "publisher": pub_counters, "wall_s": wall_s, "peers": peers,
            "link_wait_s": link_wait_s, "publish_call_us": call_us}


def fly_samples(duration_s: float, seed: int) -> list[Any]:
    """Estimator inputs (arrival order) of a SimVehicle hover flight on the test city."""
    from companion.mission import load_mission
    from simvehicle import SimVehicle

    mission = load_mission("test")
    sim = SimVehicle(mission, 0, seed)
    samples: list[Any] = []
    for _ in range(int(duration_s / 0.05)):
        out = sim.advance(None, None)
        imu_and_attitude: list[ImuSample | AttitudeSample] = [*out.imu, *out.attitude]
        samples += sorted(imu_and_attitude, key=lambda s: s.t_us) + list(out.gnss)
    return samples


def run_estimator(samples: list[Any], pub: TelemetryPublisher | None,
                  wall_rate: bool = True) -> tuple[float, list[Any]]:
    """(wall s, [(estimate, counters)] at 50 Hz) running the estimator as fast as possible.

    ``wall_rate``: publish each topic at its default rate in WALL time (what a node does at real
    time; faster than that it keeps the latest); otherwise at the simulated rate (a stress test).
    """
    from companion.domain.samples import ImuSample
    from companion.wiring import navigator_for

    nav = navigator_for(None)
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

    # a publisher on a private hub nobody joins: "no subscribers", measured alternately with the
    # attached one (pairs of runs), so the host's load drifts cancel in the ratio
    cfg_alone = TelemetryConfig.from_env({**env, "BELIEFNAV_ZENOH_HUB": f"tcp/127.0.0.1:{_free_port()}"})
    rtf: dict[str, list[float]] = {k: [] for k in ("bare", "none", "ten", "stress_none", "stress_ten")}
    cpu_rtf: dict[str, list[float]] = {k: [] for k in rtf}  # process CPU time: this process's threads only
    procs = _start_subscribers(1, env)
    try:
        single = fan_out(fan_s, cfg, flight, procs, SINGLE_VEHICLE)
        procs += _start_subscribers(N_SUBSCRIBERS - 1, env)
        time.sleep(SETTLE_S)
        fan = fan_out(fan_s, cfg, flight, procs)
        # counted now: the stress runs below leave a backlog that a subscriber may not drain by the
        # end (its final counts would then be lost, read as "nothing delivered")
        delivered = _snapshot_subscribers(procs)
        with TelemetryPublisher(RTF_VEHICLE, "companion", cfg_alone) as alone, \
                TelemetryPublisher(RTF_VEHICLE, "companion", cfg) as attached:
            await_receiving(attached, procs)
            # the stress runs last: they leave the subscribers a backlog that would load the others
            for runs in ((("bare", None, True), ("none", alone, True), ("ten", attached, True)),
                         (("stress_none", alone, False), ("stress_ten", attached, False))):
                for _ in range(repeats):
                    for key, pub, wall_rate in runs:
                        cpu0 = time.process_time()
                        rtf[key].append(flight_s / run_estimator(samples, pub, wall_rate)[0])
                        cpu_rtf[key].append(flight_s / (time.process_time() - cpu0))
            time.sleep(0.5)
    finally:
        results = _stop_subscribers(procs)
    sent_total = sum(fan["sent"].values())
    lat = np.concatenate([np.asarray(r["latency_ms"].get(FANOUT_VEHICLE, []), dtype=float)
                          for r in delivered])
    lat1 = np.asarray(delivered[0]["latency_ms"].get(SINGLE_VEHICLE, []), dtype=float)
    decode = np.concatenate([np.asarray(r["decode_us"], dtype=float) for r in delivered])
    delivered_fan = [r["counts"].get(FANOUT_VEHICLE, 0) for r in delivered]
    return {
        "subscribers": N_SUBSCRIBERS,
        "publisher_peers_linked": fan["peers"],
        "rates_hz": RATES_HZ,
        "fanout_duration_s": round(fan["wall_s"], 2),
        "sent_per_subscriber": sent_total,
        "delivered_rate_hz": round(float(np.mean(delivered_fan)) / fan["wall_s"], 1),
        "delivered_fraction": round(float(np.sum(delivered_fan)) / (sent_total * N_SUBSCRIBERS), 5),
        "drops_at_default_rate": int(sent_total * N_SUBSCRIBERS - np.sum(delivered_fan)),
        "delivered_min_per_subscriber": int(min(delivered_fan)),
        "link_wait_s": round(fan["link_wait_s"], 2),
        "latency_p50_ms": round(float(np.percentile(lat, 50)), 3) if len(lat) else None,
        "latency_p99_ms": round(float(np.percentile(lat, 99)), 3) if len(lat) else None,
        "latency_max_ms": round(float(np.max(lat)), 3) if len(lat) else None,
        "latency_1_subscriber_p50_ms": round(float(np.percentile(lat1, 50)), 3) if len(lat1) else None,
        "latency_1_subscriber_p99_ms": round(float(np.percentile(lat1, 99)), 3) if len(lat1) else None,
        "delivered_1_subscriber": int(delivered[0]["counts"].get(SINGLE_VEHICLE, 0)),
        "sent_1_subscriber": sum(single["sent"].values()),
        "publish_call_us_p50": round(float(np.percentile(fan["publish_call_us"], 50)), 1),
        "publish_call_us_p99": round(float(np.percentile(fan["publish_call_us"], 99)), 1),
        "subscriber_decode_us_p50": round(float(np.median(decode)), 1) if len(decode) else None,
        "malformed": int(sum(r["malformed"] for r in results)),
        "subscribers_not_stopped_in_time": int(sum(bool(r.get("lost")) for r in results)),
        "estimator_realtime_factor_no_subscribers": round(float(np.median(rtf["none"])), 1),
        "estimator_realtime_factor_10_subscribers": round(float(np.median(rtf["ten"])), 1),
        "realtime_factor_ratio": round(float(np.median(np.divide(rtf["ten"], rtf["none"]))), 3),
        "estimator_realtime_factor_without_telemetry": round(float(np.median(rtf["bare"])), 1),
        "estimator_cpu_realtime_factor_no_subscribers": round(float(np.median(cpu_rtf["none"])), 1),
        "estimator_cpu_realtime_factor_10_subscribers": round(float(np.median(cpu_rtf["ten"])), 1),
        "cpu_realtime_factor_ratio": round(float(np.median(np.divide(cpu_rtf["ten"], cpu_rtf["none"]))), 3),
        "stress_sim_rate_realtime_factor_no_subscribers": round(float(np.median(rtf["stress_none"])), 1),
        "stress_sim_rate_realtime_factor_10_subscribers": round(float(np.median(rtf["stress_ten"])), 1),
        "estimator_flight_s": flight_s,
    }


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
