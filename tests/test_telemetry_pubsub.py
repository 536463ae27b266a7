"""Publisher -> subscriber over real Zenoh on 127.0.0.1, in separate processes."""

import json
import os
import subprocess
import sys
import threading
import time
from collections import Counter

import numpy as np
import pytest
from telemetry_helpers import child, hub_env

from companion.domain.samples import Setpoint
from companion.errors import UserError
from companion.telemetry import codec as zc
from companion.telemetry.pubsub import TelemetryConfig, TelemetryPublisher, TelemetrySubscriber, open_session

pytestmark = [pytest.mark.slow, pytest.mark.timeout(60)]


def cfg_of(env: dict[str, str]) -> TelemetryConfig:
    return TelemetryConfig.from_env(env)


def test_synthetic_flight_reaches_a_subscriber_in_another_process_and_malformed_are_counted():
    env = hub_env()
    got: Counter[str] = Counter()
    lock = threading.Lock()

    def on(msg):
        with lock:
            got[f"{msg.process}/{msg.topic}"] += 1

    with TelemetrySubscriber(on, cfg_of(env)) as sub, child(
        ["-m", "gcs_tools.synth", "--duration-s", "1", "--speed", "4", "--wait-subscriber",
         "--malformed", "3"],
        env,
    ) as proc:
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        sent = json.loads(out.strip().splitlines()[-1])
        deadline = time.monotonic() + 5
        total_sent = sum(c["published"] for c in sent.values())
        while sum(got.values()) < total_sent and time.monotonic() < deadline:
            time.sleep(0.05)
        # every well-formed message arrives, decoded; the 3 malformed ones are counted, not fatal
        assert sum(got.values()) == total_sent
        assert got["companion/estimate"] == 50 and got["vehicle/truth"] == 50 and got["vehicle/gnss"] == 10
        assert {"companion/belief", "companion/health", "bridge/setpoint", "bridge/route"} <= set(got)
        assert sub.malformed_total == 3


def test_stalled_and_crashed_subscribers_cost_the_publisher_nothing():
    """A subscriber whose callback never returns, and one killed mid-run: publish() stays cheap,
    nothing blocks, and a healthy subscriber keeps receiving."""
    env = hub_env()
    stall = (
        "import time, sys\n"
        "from companion.telemetry.pubsub import TelemetrySubscriber\n"
        "s = TelemetrySubscriber(lambda m: time.sleep(3600))\n"
        "print('ready', flush=True); time.sleep(3600)\n"
    )
    healthy: list[int] = []
    sp = Setpoint(0, np.zeros(3), np.ones(3), np.zeros(3))
    with child(["-c", stall], env) as stalled, child(["-c", stall], env) as crashed:
        assert stalled.stdout.readline().strip() == "ready"
        assert crashed.stdout.readline().strip() == "ready"
        with TelemetryPublisher("uav9", "bridge", cfg_of(env)) as pub, TelemetrySubscriber(
            lambda m: m.topic == "setpoint" and healthy.append(m.obj.t_us), cfg_of(env),
            # the healthy subscriber shares this process (and its GIL) with the publisher: it takes
            # only the setpoints, so decoding 20,000 big routes here does not time the publisher
            key_expr="beliefnav/uav9/bridge/setpoint",
        ):
            assert pub.wait_for_subscribers("setpoint")
            time.sleep(1.0)  # let gossip link every peer
            call_s = []
            n = 20_000
            # ~8 kB, encoded once: fills TCP buffers fast
            big = zc.encode("route", zc.RouteInfo(0, "x" * 2000, 0, np.zeros((200, 3)), 1.0), 0)
            for k in range(n):
                t0 = time.perf_counter()
                pub.publish("setpoint", Setpoint(k, sp.p_ned_m, sp.v_ned_m_s, sp.a_ned_m_s2))
                pub.put_raw("route", big)
                call_s.append(time.perf_counter() - t0)
                if k == n // 2:
                    crashed.kill()
                if k % 100 == 0:
                    time.sleep(0.001)
            counts = pub.counters()
        # once the stalled subscriber's buffers are full (second half) the calls stay cheap: a publisher
        # that waited for it would block for good. (Single calls can be preempted for tens of ms on a
        # loaded host, with or without subscribers, so the maximum says nothing.)
        p50_ms, p99_ms = np.percentile(call_s[n // 2:], [50, 99]) * 1e3
        assert p50_ms < 1 and p99_ms < 5, (p50_ms, p99_ms)
        assert counts["published"] == n and counts["put_errors"] == 0
        assert stalled.poll() is None  # it really was alive and stalled all along
        assert len(healthy) > 1000 and healthy == sorted(healthy)


def test_interpreter_exits_with_open_sessions_and_live_peers():
    """A process that forgets to close its publisher and subscriber still exits promptly."""
    env = hub_env()
    forgetful = (
        "import numpy as np\n"
        "from companion.telemetry.pubsub import TelemetryPublisher, TelemetrySubscriber\n"
        "from companion.domain.samples import Setpoint\n"
        "s = TelemetrySubscriber(lambda m: None)\n"
        "p = TelemetryPublisher('uav1', 'bridge')\n"
        "p.publish('setpoint', Setpoint(0, np.zeros(3), np.zeros(3), np.zeros(3)))\n"
        "print('bye', flush=True)\n"
    )
    with TelemetrySubscriber(lambda m: None, cfg_of(env)):
        t0 = time.monotonic()
        out = subprocess.run([sys.executable, "-c", forgetful], env=env, capture_output=True, text=True,
                             timeout=30)
        assert out.returncode == 0, out.stderr
        assert out.stdout.strip() == "bye" and time.monotonic() - t0 < 20


def test_broken_config_file_is_one_line_user_error(tmp_path):
    bad = tmp_path / "zenoh.json5"
    bad.write_text("{ mode: 'nonsense' }")
    with pytest.raises(UserError, match="zenoh.json5: cannot open a Zenoh session") as info:
        open_session(TelemetryConfig(zenoh_config_file=str(bad)))
    assert "\n" not in str(info.value)


def test_disabled_telemetry_opens_nothing():
    pub = TelemetryPublisher("uav1", "companion", TelemetryConfig.from_env({"BELIEFNAV_TELEMETRY": "off"}))
    pub.publish("belief", zc.Belief(0, 1.0, 0.0, "naive"))
    assert pub.counters()["published"] == 0
    pub.close()
    assert os.environ.get("BELIEFNAV_TELEMETRY") != "off"  # read from the mapping given, not os.environ


def test_bench_waits_until_every_subscriber_process_receives_the_publisher():
    """The bench's start gate: a subscriber on another mesh never receives, and the gate says so
    instead of letting a run count it as 100 % drops; subscribers on the mesh all pass it."""
    from gcs_tools.bench.telemetry import _start_subscribers, _stop_subscribers, await_receiving

    env, other = hub_env(), hub_env()
    procs = _start_subscribers(2, env)
    try:
        with TelemetryPublisher("gate", "companion", cfg_of(env)) as pub:
            assert await_receiving(pub, procs, timeout_s=20.0) < 20.0
        lost = _start_subscribers(1, other)
        try:
            with TelemetryPublisher("gate", "companion", cfg_of(env)) as pub, \
                    pytest.raises(RuntimeError, match="only 0 of 1 subscribers received"):
                await_receiving(pub, lost, timeout_s=1.5)
        finally:
            _stop_subscribers(lost)
    finally:
        results = _stop_subscribers(procs)
    assert all(r["malformed"] == 0 for r in results)


def test_nothing_is_encoded_while_no_subscriber_matches():
    env = hub_env()
    got: list[int] = []
    belief = zc.Belief(1, 0.5, 1.0, "naive")
    with TelemetryPublisher("uav1", "companion", cfg_of(env)) as pub:
        pub.publish("belief", belief)
        pub.publish("belief", "not a Belief")  # would be an encode error, but is never encoded
        assert pub.counters() == {"published": 0, "unmatched": 2, "encode_errors": 0, "put_errors": 0}
        with TelemetrySubscriber(lambda m: got.append(m.obj.t_us), cfg_of(env)):
            assert pub.wait_for_subscribers("belief")
            pub.publish("belief", belief)
            deadline = time.monotonic() + 5
            while not got and time.monotonic() < deadline:
                time.sleep(0.01)
        assert got == [1] and pub.counters()["published"] == 1
        pub.publish("no/such topic", belief)  # counted, never raised
        assert pub.counters()["put_errors"] == 1
        deadline = time.monotonic() + 5  # the subscriber left: back to the free path
        while pub.has_subscribers("belief") and time.monotonic() < deadline:
            time.sleep(0.01)
        pub.publish("belief", belief)
        assert pub.counters()["unmatched"] == 3
