"""Synthetic telemetry source: a vehicle circling a block, published like the SITL processes do.

For tests and benchmarks of the ground tools without a simulator:
``python -m gcs_tools.synth --vehicle uav1 --duration-s 5``. Topic rates follow the nodes:
truth/estimate 50 Hz, gnss 10 Hz, belief/setpoint 5 Hz, health 2 Hz, route and status 1 Hz (simulated time;
``--speed`` runs faster than real time). Every random draw comes from one seeded generator.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix, NavEstimate, Setpoint, TruthState
from companion.telemetry import codec as zc
from companion.telemetry.pubsub import TelemetryConfig, TelemetryPublisher

TICK_US = 20_000  # 50 Hz base tick
HOME = LocalNedFrame(47.0, 8.0, 400.0)  # the synthetic city's origin
RADIUS_M, SPEED_M_S, ALT_M = 40.0, 5.0, 20.0
BUILDINGS_NE_M = np.array([[-15.0, -15.0, 15.0, 15.0], [50.0, -30.0, 70.0, -10.0],
                           [-70.0, 20.0, -55.0, 45.0]])  # n0, e0, n1, e1 [m]


def messages(duration_s: float, rng: np.random.Generator) -> Iterator[tuple[str, str, Any]]:
    """(process, topic, object) in publishing order for a ``duration_s`` flight."""
    omega = SPEED_M_S / RADIUS_M
    angles = np.linspace(0, 2 * np.pi, 33)
    waypoints = np.column_stack([RADIUS_M * np.cos(angles), RADIUS_M * np.sin(angles), np.full(33, -ALT_M)])
    route = zc.RouteInfo(0, "synthetic", 0, waypoints, 2 * np.pi / omega, BUILDINGS_NE_M, waypoints[-1],
                         np.array([HOME.home_lat_deg, HOME.home_lon_deg, HOME.home_alt_m]))
    bias = np.zeros(3)
    beta = 0.9
    counters = {"imu_used": 0, "gnss_fused": 0, "gnss_rejected_fix_type": 0, "gnss_rejected_innovation": 0}
    for k in range(int(duration_s * 1e6 / TICK_US)):
        t_us = k * TICK_US
        a = omega * t_us * 1e-6
        p = np.array([RADIUS_M * np.cos(a), RADIUS_M * np.sin(a), -ALT_M])
        v = SPEED_M_S * np.array([-np.sin(a), np.cos(a), 0.0])
        near = float(np.clip(1 - abs(np.sin(2 * a)), 0, 1))  # "urban canyon" twice per lap
        bias = 0.94 * bias + rng.normal(0, 0.3 * near + 0.02, 3) * [1, 1, 0]
        latency_s = 0.1 + 0.6 * near + abs(rng.normal(0, 0.03))
        beta = float(np.clip(beta + 0.05 * ((1 - near) - beta) + rng.normal(0, 0.01), 0, 1))
        err = rng.normal(0, 0.1 + 0.5 * near, 3)
        counters["imu_used"] += 4
        if k % 50 == 0:
            yield "bridge", "route", dataclasses.replace(route, t_us=t_us)
            yield "vehicle", "status", zc.FlightStatus(t_us, "HOLD" if near > 0.95 else "OFFBOARD", True)
        q = np.array([1.0, 0, 0, 0])
        yield "vehicle", "truth", TruthState(t_us, p, v, q, bias, latency_s, 10 * (1 - near))
        yield "companion", "estimate", NavEstimate(
            t_us, p + err, v, bias * beta, np.full(9, 0.1), beta, float(rng.chisquare(2)), "second-order",
            gnss_rejected_innovation=counters["gnss_rejected_innovation"])
        if k % 5 == 0:
            rejected = near > 0.9 and rng.random() < 0.2
            counters["gnss_fused"] += not rejected
            counters["gnss_rejected_innovation"] += rejected
            t_valid_us = t_us - int(latency_s * 1e6)
            lat, lon, alt = HOME.to_geodetic(p + bias + rng.normal(0, 0.3, 3))
            fix = GnssFix(t_valid_us, lat, lon, alt, 3, 12, 0.8, 0.8, hdop=0.9)
            yield "vehicle", "gnss", zc.GnssReport(t_us, fix)
        if k % 10 == 0:
            yield "companion", "belief", zc.Belief(t_us, beta, float(rng.chisquare(2)), "second-order")
            yield "bridge", "setpoint", Setpoint(t_us, p, v, np.zeros(3))
        if k % 25 == 0:
            yield "companion", "health", zc.Health(t_us, dict(counters))
    yield "companion", "health", zc.Health(t_us, dict(counters), status="ended")  # a clean finish


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--vehicle", default="uav1")
    ap.add_argument("--duration-s", type=float, default=10.0, help="simulated flight time")
    ap.add_argument("--speed", type=float, default=1.0, help="times real time (0: as fast as possible)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--wait-subscriber", action="store_true", help="start only once a subscriber is there")
    ap.add_argument("--malformed", type=int, default=0, help="also publish this many malformed payloads")
    args = ap.parse_args(argv)
    pubs: dict[str, TelemetryPublisher] = {}
    cfg = TelemetryConfig.from_env()
    try:
        for proc in ("vehicle", "companion", "bridge"):
            pubs[proc] = TelemetryPublisher(args.vehicle, proc, cfg)
        first_topic = {"vehicle": "truth", "companion": "estimate", "bridge": "route"}
        if args.wait_subscriber and not all(p.wait_for_subscribers(first_topic[k]) for k, p in pubs.items()):
            print("synth: no subscriber appeared", file=sys.stderr)
            return 1
        t0 = time.monotonic()
        for n, (proc, topic, obj) in enumerate(messages(args.duration_s, np.random.default_rng(args.seed))):
            if args.speed > 0:
                lag = obj.t_us * 1e-6 / args.speed - (time.monotonic() - t0)
                if lag > 0:
                    time.sleep(lag)
            pubs[proc].publish(topic, obj)
            if n < args.malformed:
                pubs[proc].put_raw(topic, b'{"t_us": "oops"')
        print(json.dumps({proc: p.counters() for proc, p in pubs.items()}), flush=True)
    finally:
        for p in pubs.values():
            p.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
