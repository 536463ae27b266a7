"""Fuzz a live signed lockstep flight: 10^5 hostile datagrams at all five UDP ports.

Three real processes fly the test mission with signing on (as ``beliefnav sitl`` does by
default). From 8 s of simulated time a seeded generator (tests/fuzz_frames.py) fires random
bytes, bit flips, truncations, unsigned and wrong-key frames, wrong system and component ids,
and correctly signed messages of every input type with NaN/inf/extreme values, unsupported frames
and far future/past stamps at the vehicle's three ports, the estimator and the bridge, paced by
simulated time (and by the receivers' socket queues, so the kernel drops nothing). Then:

- no process died and no handler raised; the flight reached its goal;
- every datagram is accounted for: each receiver counted exactly the datagrams its peer sent plus
  the fuzz sent to it; each correctly signed hostile message was rejected by its node (the sum
  of the node's rejection counters equals the number sent, exactly); the rest moved the link's
  rejection counters.
"""

from __future__ import annotations

import json
import socket
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from fuzz_frames import FUZZ_START_S, FrameFuzzer
from sitl_helpers import Trio, require_pieces, route_duration_s

MISSION = "test"
SEED = 13
N_FRAMES = 100_000
BATCH = 200
MAX_RX_QUEUE_BYTES = 400_000  # pause while a receiver has this much unread (no kernel drops)


def _udp_table() -> dict[int, tuple[int, int]]:
    """Local UDP port -> (bytes queued for reading, datagrams the kernel dropped), 127.0.0.1 only."""
    table = {}
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        f = line.split()
        addr, port = f[1].split(":")
        if addr == "0100007F":
            table[int(port, 16)] = (int(f[4].split(":")[1], 16), int(f[-1]))
    return table


def _rejections(counters: dict[str, int], prefixes: tuple[str, ...]) -> int:
    return sum(n for k, n in counters.items() if k.startswith(prefixes))


LINK_REJECTIONS = ("garbage", "bad_crc", "unknown_message", "bad_signature", "wrong_system_id",
                   "wrong_component_id")


def test_hostile_frames_at_every_port_are_counted_and_the_signed_flight_still_arrives(tmp_path):
    require_pieces()
    from companion.mavlink.udp_link import read_signing_key
    from simvehicle.harness.sitl.launcher import SitlOptions, write_fresh_key
    from simvehicle.harness.sitl.supervisor import free_udp_ports

    key_file = tmp_path / "signing.key"
    write_fresh_key(key_file)
    out = tmp_path / "run"
    route_s = route_duration_s(MISSION, 0)
    opts = SitlOptions(MISSION, 0, "second-order", SEED, out, route_s + 60, signing_key_file=key_file)
    est_port, bridge_port = free_udp_ports(2)
    trio = Trio(out, opts, estimator_bind_port=est_port, bridge_bind_port=bridge_port)
    ports = {"vehicle_estimator": trio.ports[0], "vehicle_bridge": trio.ports[1], "ground": trio.ports[2],
             "estimator": est_port, "bridge": bridge_port}
    fuzzer = FrameFuzzer(np.random.default_rng(SEED), read_signing_key(key_file))
    sent: Counter[tuple[str, str]] = Counter()
    t_end_s = FUZZ_START_S + 0.6 * route_s  # every frame is out well before the goal
    drops_seen = 0
    try:
        trio.wait_sim_time(FUZZ_START_S, 60)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            n = 0
            while n < N_FRAMES:
                t_s = trio.poll_progress()
                assert trio.vehicle.poll() is None, "vehicle ended while fuzzing"
                quota = N_FRAMES * min(1.0, (t_s - FUZZ_START_S + 1.0) / (t_end_s - FUZZ_START_S))
                table = _udp_table()
                busy = any(table.get(p, (0, 0))[0] > MAX_RX_QUEUE_BYTES for p in ports.values())
                if n >= quota or busy:
                    time.sleep(0.002)
                    continue
                for fuzz in fuzzer.frames(min(BATCH, N_FRAMES - n)):
                    sock.sendto(fuzz.data, ("127.0.0.1", ports[fuzz.target]))
                    sent[fuzz.target, fuzz.expect] += 1
                n = sum(sent.values())
            table = _udp_table()
            drops_seen = sum(table.get(p, (0, 0))[1] for p in ports.values())
        t_fuzz_done = trio.poll_progress()
        alive = {name: p.poll() is None for name, p in trio.sup.children.items()}
        vehicle = trio.wait_vehicle(120)
        time.sleep(1.2)  # the companions' counters of the last second reach their files
        alive.update({name: p.poll() is None for name, p in trio.sup.children.items() if name != "vehicle"})
    finally:
        trio.stop()
    est = json.loads((out / "estimator.json").read_text())
    bridge = json.loads((out / "bridge.json").read_text())
    assert all(alive.values()), alive
    assert drops_seen == 0
    assert sum(sent.values()) == N_FRAMES and t_fuzz_done < route_s
    assert vehicle["outcome"] == "reached_goal" and vehicle["collisions"] == 0, vehicle["outcome"]

    def n(target: str, expect: str | None = None) -> int:
        return sum(v for (t, e), v in sent.items() if t == target and (expect is None or e == expect))

    # no handler ever raised
    for node in (vehicle["node"], est["node"], bridge["node"]):
        assert not [k for k in node if k.startswith("handler_error")], node
    # datagrams: exactly what the peer sent plus the fuzz (the vehicle stops first: its peers'
    # heartbeats of the last second may still leave after it closed)
    links = vehicle["links"]
    assert est["link"]["datagrams_rx"] == links["estimator"]["datagrams_tx"] + n("estimator")
    assert bridge["link"]["datagrams_rx"] == links["bridge"]["datagrams_tx"] + n("bridge")
    assert vehicle["ground"]["datagrams_rx"] == n("ground")
    for name, peer in (("estimator", est), ("bridge", bridge)):
        legit = links[name]["datagrams_rx"] - n(f"vehicle_{name}")
        assert 0 <= peer["link"]["datagrams_tx"] - legit <= 5, name
    # signed hostile messages: each rejected by its node, exactly
    assert _rejections(est["node"], ("rejected_",)) == n("estimator", "node"), est["node"]
    assert bridge["node"].get("rejected_clock_marker", 0) == n("bridge", "node"), bridge["node"]
    veh_rejected = _rejections(vehicle["node"], ("rejected_", "clock_alarm_"))
    assert veh_rejected == n("vehicle_estimator", "node") + n("vehicle_bridge", "node"), vehicle["node"]
    ground_counted = _rejections(vehicle["node"], ("ground_",))
    assert ground_counted == vehicle["ground"]["messages_rx"] == n("ground", "ground")
    # the rest: refused by the links, at least one counted rejection per datagram
    for counters, target in ((est["link"], "estimator"), (bridge["link"], "bridge"),
                             (links["estimator"], "vehicle_estimator"), (links["bridge"], "vehicle_bridge"),
                             (vehicle["ground"], "ground")):
        assert _rejections(counters, LINK_REJECTIONS) >= n(target, "link"), (target, counters)
    # and the estimate stayed good: the fuzz did not move it
    assert est["navigator"]["gnss_fused"] > 0.8 * vehicle["gnss_sent"]


if __name__ == "__main__":  # pragma: no cover
    pytest.main([__file__, "-q"])
