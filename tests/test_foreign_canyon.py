"""The canyon receiver beside a foreign autopilot, its pure parts: driven by another simulator's truth
stream it measures the same epochs for the same seed, sends exactly the receiver's single-point
solution of the epochs it records (with the GPS time of the measurement on the wire), and the
tightly coupled rows are scored on those recorded epochs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.errors import UserError
from companion.gnss.ephemeris import attach_broadcast
from companion.gnss.spp import SppConfig, solve_position
from companion.gnss.timescale import week_tow
from companion.mission import load_mission
from simvehicle.config import ReceiverConfig
from simvehicle.harness.ardupilot.config import FEEDS, GPS2_ID, ArduPilotConfig, ardupilot_parameters
from simvehicle.harness.ardupilot.flight import ArduPilotFlightOptions
from simvehicle.harness.ardupilot.gnss_source import gps_input_fields
from simvehicle.harness.foreign.analysis import SPP_ROW, errors, held_track, tight_track
from simvehicle.harness.foreign.canyon_source import CanyonGnssSource
from simvehicle.harness.foreign.flight import plan_flight, tight_arguments
from simvehicle.harness.foreign.gnss_source import UrbanGnssSource
from simvehicle.harness.foreign.recording import Recording
from simvehicle.harness.foreign.scoring import raw_tracks
from simvehicle.harness.px4.config import Px4FlightConfig, px4_parameters
from simvehicle.harness.px4.flight import Px4FlightOptions, fly_px4

G_M_S2 = 9.80665
T_OFFSET_US = 7_000  # the autopilot's truth stamps are not on the receiver's grid


def _truth(seconds: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """50 Hz truth: along the test city's cross street (north 52 m), 3 m/s east, 15 m up."""
    t_us = np.arange(0, round(seconds * 1e6), 20_000) + T_OFFSET_US
    t = (t_us - T_OFFSET_US) * 1e-6
    p = np.column_stack([np.full_like(t, 52.0), 5.0 + 3.0 * t, np.full_like(t, -15.0)])
    v = np.tile([0.0, 3.0, 0.0], (len(t), 1))
    return t_us, p, v


def _flown(seed: int, seconds: float = 12.0, velocity: bool = True) -> CanyonGnssSource:
    m = load_mission("test", "canyon")
    rng = np.random.default_rng(seed)
    src = CanyonGnssSource(ReceiverConfig(enabled=True), m.world, m.frame, rng, velocity)
    for t, p, v in zip(*_truth(seconds), strict=True):
        src.on_truth(int(t), p, v)
        src.due(int(t))
    return src


@pytest.fixture(scope="module")
def flown() -> CanyonGnssSource:
    return _flown(3)


def test_same_seed_same_observations_and_fixes_another_seed_another_sky(flown):
    a, b, c = flown, _flown(3), _flown(4)
    assert len(a.raw) == len(b.raw) >= 55  # 5 Hz for 12 s, the last still in flight
    for x, y in zip(a.raw, b.raw, strict=True):
        assert x.t_us == y.t_us and x.arrival_us == y.arrival_us and x.t_gps_s == y.t_gps_s
        for name in ("system", "prn", "pseudorange_m", "pseudorange_rate_m_s", "cn0_dbhz"):
            np.testing.assert_array_equal(getattr(x.epoch, name), getattr(y.epoch, name))
    for x, y in zip(a.sent, b.sent, strict=True):
        np.testing.assert_array_equal(x.p_ned_m, y.p_ned_m)
        np.testing.assert_array_equal(x.v_ned_m_s, y.v_ned_m_s)
        assert (x.fix.lat_deg, x.fix.lon_deg, x.fix.h_acc_m, x.t_gps_s) == (y.fix.lat_deg, y.fix.lon_deg,
                                                                          y.fix.h_acc_m, y.t_gps_s)
    assert a.model.t0_gps_s != c.model.t0_gps_s  # each seed its time of day, so its sky
    # one epoch per receiver period, measured at the truth's own (off-grid) stamps, released 80 ms later
    t = np.array([r.t_us for r in a.raw])
    assert np.all(np.diff(t) == 200_000) and t[0] == T_OFFSET_US
    assert {r.arrival_us - r.t_us for r in a.raw} == {80_000}  # truth every 20 ms: on time


def test_the_fix_sent_is_the_receivers_spp_of_the_recorded_epoch(flown):
    """Each fix sent is an independent single-point solution of the raw epoch the flight recorded
    (broadcast satellite states, Klobuchar and Saastamoinen evaluated by the solver itself at its own
    estimate, where the receiver used the antenna: millimetres), valid at the epoch's time; the
    GPS_INPUT carries its position, accuracy, velocity and the GPS time of the measurement."""
    src, store = flown, flown.model.store
    cfg = ReceiverConfig()
    by_t = {r.t_us: r for r in src.raw}
    assert len(src.sent) >= 50 and src.model.unsolved == 0
    for sf in src.sent:
        raw = by_t[sf.fix.t_validity_us]
        assert sf.arrival_us == raw.arrival_us
        ep, _ = attach_broadcast(raw.epoch, store)
        sol = solve_position(ep, SppConfig(weighting=cfg.weighting, raim=cfg.raim), klobuchar=store.klobuchar)
        assert sol.ok
        np.testing.assert_allclose(src.model.to_ned_m(sol.p_ecef_m), sf.p_ned_m, atol=0.02)
        assert sf.fix.h_acc_m == pytest.approx(sol.h_acc_m, rel=1e-3)
        assert sf.t_gps_s == pytest.approx(src.model.t0_gps_s + raw.t_us * 1e-6, abs=1e-9)
    sf = src.sent[20]
    f = gps_input_fields(sf, GPS2_ID)
    week, tow = week_tow(sf.t_gps_s)
    assert (f["time_week"], f["time_week_ms"]) == (week, round(tow * 1000)) and f["gps_id"] == GPS2_ID
    assert f["horiz_accuracy"] == pytest.approx(sf.fix.h_acc_m) and f["ignore_flags"] == 0
    assert f["speed_accuracy"] == pytest.approx(sf.speed_accuracy_m_s) and math.isfinite(f["speed_accuracy"])
    assert (f["vn"], f["ve"], f["vd"]) == pytest.approx(tuple(sf.v_ned_m_s))
    # the receiver's Doppler velocity, not the truth's: within a few dm/s of 3 m/s east
    v = np.array([s.v_ned_m_s for s in src.sent])
    assert np.median(np.abs(v[:, 1] - 3.0)) < 0.5 and np.any(v[:, 1] != 3.0)
    # canyon errors: metres to tens of metres, not the truth
    t_s = np.array([s.fix.t_validity_us - T_OFFSET_US for s in src.sent]) * 1e-6
    p_true = np.column_stack([np.full_like(t_s, 52.0), 5.0 + 3.0 * t_s])
    e = np.hypot(*(np.array([s.p_ned_m[:2] for s in src.sent]) - p_true).T)
    assert 1.0 < np.median(e) < 60.0


def test_position_only_fixes_without_velocity():
    src = _flown(3, seconds=2.0, velocity=False)
    assert src.sent and all(s.v_ned_m_s is None and math.isnan(s.speed_accuracy_m_s) for s in src.sent)
    f = gps_input_fields(src.sent[0])
    assert f["ignore_flags"] != 0 and f["speed_accuracy"] == 0.0


def test_tight_rows_are_scored_on_the_recorded_epochs(flown):
    """A level, unaccelerated IMU stream along the truth: every tight row estimates (within the canyon's
    errors), and row spp is the fix that had arrived."""
    t_us, p, _ = _truth(12.0)
    rec = Recording(imu_t_us=t_us.tolist(), imu_acc_frd_m_s2=[np.array([0.0, 0.0, -G_M_S2])] * len(t_us),
                    imu_q_ned_frd=[np.array([1.0, 0.0, 0.0, 0.0])] * len(t_us))
    m = load_mission("test", "canyon")
    times = t_us[100:]  # from 2 s on
    tracks = raw_tracks(flown, m, times, ("cn0-elevation", "second-order"), rec)
    assert set(tracks) == {SPP_ROW, "tight-cn0-elevation", "tight-second-order"}
    truth = p[100:]
    for name, tr in tracks.items():
        _, eh = errors(tr.p_ned_m, truth)
        assert np.isfinite(eh).all() and np.median(eh) < 60.0, name
    # the spp row holds the latest arrived fix: at an arrival instant it is that fix
    sf = flown.sent[30]
    held = held_track(np.array([s.arrival_us for s in flown.sent]), np.array([s.p_ned_m for s in flown.sent]),
                      np.array([sf.arrival_us, sf.arrival_us - 1]))
    np.testing.assert_array_equal(held.p_ned_m[0], sf.p_ned_m)
    np.testing.assert_array_equal(held.p_ned_m[1], flown.sent[29].p_ned_m)
    assert tracks["tight-second-order"].counters["gnss_rejected_no_ephemeris"] == 0
    # the rows run in the flown mission's city: its map is the belief's line-of-sight prior (the
    # belief row moves without it), a prior the weightings without a belief do not read
    store = flown.model.store
    for w in ("cn0-elevation", "second-order"):
        nomap = tight_track(rec, flown.raw, w, store, m, times, map_prior=False).p_ned_m
        same = np.array_equal(nomap, tracks[f"tight-{w}"].p_ned_m)
        assert same == (w == "cn0-elevation"), w


def test_the_scenario_picks_the_source(tmp_path):
    def plan(scenario: str | None, feed: str = "none"):
        opts = ArduPilotFlightOptions("test", 2, "second-order", 0, tmp_path, feed=feed, scenario=scenario)
        return plan_flight("ardupilot", opts, ArduPilotConfig(), FEEDS)

    canyon = plan("canyon", "gps-input")
    assert isinstance(canyon.source, CanyonGnssSource) and canyon.canyon is canyon.source
    assert canyon.velocity_sigma_m_s is None and canyon.closed
    assert isinstance(plan(None).source, UrbanGnssSource) and plan(None).canyon is None
    with pytest.raises(UserError, match="--scenario mismatch: with --vehicle ardupilot, one of paper, can"):
        plan("mismatch")
    assert tight_arguments(None) == ()


def test_parameters_with_the_raw_receiver_and_px4s_open_loop_only(tmp_path):
    """EKF3's and EKF2's GNSS pre-flight checks are off with the raw receiver (and only then); PX4's
    closed loop is refused before any process starts (its SYSTEM_TIME is the host's clock)."""
    assert ardupilot_parameters(ArduPilotConfig(), "gps-input", canyon=True) == {
        **ardupilot_parameters(ArduPilotConfig(), "gps-input"), "EK3_GPS_CHECK": 0}
    assert "EK3_GPS_CHECK" not in ardupilot_parameters(ArduPilotConfig())
    # the closed loops' second receiver declares the canyon receiver's latency (the companion's clock lag)
    for feed in ("gps-input", "vision"):
        params = ardupilot_parameters(ArduPilotConfig(), feed, True, receiver_latency_ms=80)
        assert params["GPS2_DELAY_MS"] == 80
    open_loop = ardupilot_parameters(ArduPilotConfig(), "none", True, receiver_latency_ms=80)
    assert open_loop["GPS1_DELAY_MS"] == 100 and "GPS2_DELAY_MS" not in open_loop
    assert px4_parameters(Px4FlightConfig(), canyon=True)["EKF2_GPS_CHECK"] == 0
    assert "EKF2_GPS_CHECK" not in px4_parameters(Px4FlightConfig())
    with pytest.raises(UserError, match="open loop only"):
        fly_px4(Px4FlightOptions("test", 2, "second-order", 0, tmp_path, feed="odometry", scenario="canyon"))
    assert not (tmp_path / "px4").exists()


def test_scenario_option_errors_beside_an_autopilot_are_one_line(tmp_path, capsys):
    from gcs_tools.cli import main

    for cmd in (["sitl", "--vehicle", "ardupilot"], ["evaluate", "--vehicle", "px4"]):
        assert main([*cmd, "--mission", "test", "--scenario", "realistic", "--out", str(tmp_path / "x")]) == 2
        assert "--scenario realistic: with --vehicle" in capsys.readouterr().err
    assert main(["sitl", "--vehicle", "ardupilot", "--scenario", "canyn", "--out", str(tmp_path / "y")]) == 2
    assert "canyon" in capsys.readouterr().err  # not one of the scenarios: the nearest named
