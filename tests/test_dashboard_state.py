"""Live state: known-answer estimation error, frames carry each point once, history bounded."""

import numpy as np

from companion.domain.samples import NavEstimate, TruthState
from companion.telemetry import codec as zc
from companion.telemetry.pubsub import Received
from gcs_tools.dashboard.state import LiveState


def msg(process, topic, obj, vehicle="uav1"):
    return Received(vehicle, process, topic, obj, None, 0, b"")


def test_error_frames_and_history():
    st = LiveState(history_len=3)
    for k in range(5):
        t = k * 20_000
        q = np.r_[1.0, 0, 0, 0]
        st.ingest(msg("vehicle", "truth", TruthState(t, np.array([k, 0.0, -5]), np.zeros(3), q)))
        st.ingest(msg("companion", "estimate",
                      NavEstimate(t + 1000, np.array([k + 3.0, 4.0, -5]), np.zeros(3), np.zeros(3),
                                  np.ones(9), 0.5, float("nan"), "naive")))
    st.ingest(msg("companion", "health", zc.Health(0, {"gnss_rejected_stale": 2})))
    st.ingest_malformed("beliefnav/uav1/vehicle/truth", b"{", "truth: not JSON")
    frame = st.take_frame()
    v = frame["vehicles"]["uav1"]
    assert [p[1] for p in v["series"]["err"]] == [5.0] * 5  # |(3, 4, 0)|
    assert v["series"]["est"][0][3:] == [] and v["series"]["est"][0][1:] == [3.0, 4.0]
    assert v["counters"] == {"companion": {"gnss_rejected_stale": 2}}
    assert frame["malformed"] == 1 and "not JSON" in frame["last_malformed"]
    assert st.take_frame()["vehicles"]["uav1"]["series"]["err"] == []  # each point sent once
    assert len(st.snapshot()["vehicles"]["uav1"]["series"]["err"]) == 3  # bounded history
    assert st.summary()["uav1"]["est_error_m"] == 5.0


def test_freshness_and_arrival_at_the_goal():
    """Frames carry seconds since each process was last heard (server clock) and whether the last
    true position is at the route's goal: what the page's live / stale / ended badge shows."""
    import time

    st = LiveState()
    q = np.r_[1.0, 0, 0, 0]
    goal = np.array([10.0, 0.0, -5.0])
    st.ingest(msg("bridge", "route", zc.RouteInfo(0, "m", 0, np.array([[0.0, 0, -5], goal]), 10.0,
                                                   goal_ned_m=goal)))
    st.ingest(msg("vehicle", "truth", TruthState(0, np.array([0.0, 0, -5]), np.zeros(3), q)))
    v = st.take_frame()["vehicles"]["uav1"]
    assert not v["at_goal"] and v["age_s"] < 0.5 and set(v["process_age_s"]) == {"bridge", "vehicle"}
    time.sleep(0.3)
    st.ingest(msg("vehicle", "truth", TruthState(1, goal + [2.5, 0, 0], np.zeros(3), q)))  # 2.5 m off
    v = st.take_frame()["vehicles"]["uav1"]
    assert v["at_goal"]
    assert v["process_age_s"]["bridge"] >= 0.3 > v["process_age_s"]["vehicle"]
    st.ingest(msg("vehicle", "truth", TruthState(2, goal + [3.5, 0, 0], np.zeros(3), q)))
    assert not st.snapshot()["vehicles"]["uav1"]["at_goal"]
