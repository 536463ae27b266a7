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


def test_fixes_are_placed_about_the_routes_home_and_a_refused_one_is_marked():
    """Fixes received before the route's home is known wait for it; each is placed exactly (known
    answer: a fix 10 m north and 20 m east of home); the fix before an estimate whose gate count
    went up is the rejected one; mode, armed, fix type, satellites, HDOP and altitude are the latest."""
    from companion.domain.geodesy import LocalNedFrame
    from companion.domain.samples import GnssFix
    from gcs_tools.dashboard.state import ended

    home = LocalNedFrame(52.52, 13.405, 35.0)
    st = LiveState()

    def fix(t_us, n, e):
        lat, lon, alt = home.to_geodetic(np.array([n, e, -15.0]))
        report = zc.GnssReport(t_us, GnssFix(t_us - 100_000, lat, lon, alt, 3, 11, 0.5, 0.7, hdop=1.2))
        return msg("vehicle", "gnss", report)

    def estimate(t_us, rejected):
        return msg("companion", "estimate", NavEstimate(
            t_us, np.array([10.0, 20.0, -15.0]), np.zeros(3), np.zeros(3), np.r_[4.0, 9.0, np.ones(7)], 0.5,
            2.0, "naive", gnss_rejected_innovation=rejected))

    st.ingest(fix(100_000, 10.0, 20.0))
    assert st.take_frame()["vehicles"]["uav1"]["series"]["fix"] == []  # no home yet: kept
    st.ingest(msg("bridge", "route", zc.RouteInfo(0, "m", 0, np.zeros((2, 3)), 1.0,
                                                   home_lla=np.array([52.52, 13.405, 35.0]))))
    st.ingest(estimate(120_000, 0))
    st.ingest(fix(200_000, -3.0, 7.5))
    st.ingest(estimate(220_000, 1))  # the gate refused the fix just received
    st.ingest(estimate(240_000, 1))
    st.ingest(msg("vehicle", "status", zc.FlightStatus(240_000, "HOLD", True)))
    v = st.take_frame()["vehicles"]["uav1"]
    (t0, n0, e0), (t1, n1, e1) = v["series"]["fix"]
    assert (t0, t1) == (0.1, 0.2) and abs(n0 - 10) < 1e-3 and abs(e0 - 20) < 1e-3
    assert abs(n1 + 3) < 1e-3 and abs(e1 - 7.5) < 1e-3
    assert v["series"]["rejected"] == [[t1, n1, e1]]
    latest = v["latest"]
    assert (latest["mode"], latest["armed"]) == ("HOLD", True)
    assert (latest["fix_type"], latest["satellites"]) == (3, 11)
    assert (latest["hdop"], latest["h_acc_m"], latest["altitude_m"]) == (1.2, 0.5, 15.0)
    assert (latest["var_n_m2"], latest["var_e_m2"]) == (4.0, 9.0)  # the map's uncertainty ellipse
    assert not ended(False, v["status"])
    st.ingest(msg("companion", "health", zc.Health(260_000, {"gnss_fused": 1}, status="ended")))
    assert ended(False, st.take_frame()["vehicles"]["uav1"]["status"])
