"""``beliefnav replay --publish``: the estimator's topics reach a subscriber, exactly as the CSV says."""

import threading
import time

import numpy as np
import pytest
from telemetry_helpers import child, hub_env
from test_replay import write_flight

from companion.telemetry.pubsub import TelemetryConfig, TelemetrySubscriber

pytestmark = [pytest.mark.slow, pytest.mark.timeout(60)]


def test_replay_publishes_estimate_belief_health_at_their_rates(tmp_path):
    log, out = tmp_path / "flight.tlog", tmp_path / "out"
    write_flight(log, seconds=4.0)  # IMU every 10 ms, late GNSS at 5 Hz
    env = hub_env()
    got: dict[str, list] = {"estimate": [], "belief": [], "health": []}
    lock = threading.Lock()

    def on(msg):
        with lock:
            assert (msg.vehicle, msg.process) == ("bench1", "companion")
            got[msg.topic].append(msg.obj)

    with TelemetrySubscriber(on, TelemetryConfig.from_env(env)):  # first: the hub
        with child(["-m", "gcs_tools", "replay", str(log), "--out", str(out), "--rate-hz", "0",
                    "--publish", "--vehicle-id", "bench1"], env) as proc:
            stdout, err = proc.communicate(timeout=50)
        assert proc.returncode == 0, err
        assert "published" in stdout
        time.sleep(0.5)
    # --rate-hz 0: one CSV row per IMU sample; the published estimates are exactly the first row and
    # then the rows on the 20 ms grid (belief: 50 ms, health: 200 ms) to the last, none missing
    table = np.loadtxt(out / "estimates.csv", delimiter=",", skiprows=1)
    t_us = np.round(table[:, 0] * 1e6).astype(int)
    for topic, period_us in (("estimate", 20_000), ("belief", 50_000), ("health", 200_000)):
        want = t_us[(t_us == t_us[0]) | (t_us % period_us == 0)]
        assert [o.t_us for o in got[topic]] == want.tolist(), topic
    rows = {t: r for t, r in zip(t_us, table, strict=True)}
    for est in got["estimate"]:
        np.testing.assert_allclose(est.p_ned_m, rows[est.t_us][1:4], rtol=1e-8, atol=1e-9)
        assert est.method == "second-order"
    for b in got["belief"]:
        assert b.beta == pytest.approx(rows[b.t_us][10], rel=1e-8)
    assert got["health"][-1].counters["imu_used"] > 300
