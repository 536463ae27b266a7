"""Pure parts of the ArduPilot flight: GNSS source, GPS_INPUT fields, flight driver, analysis."""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from companion.mavlink.codec import mavlink, new_link, pack
from companion.mission import load_mission
from simvehicle.config import GnssConfig
from simvehicle.gnss import GnssModel
from simvehicle.harness.ardupilot.config import ArduPilotConfig, ardupilot_parameters
from simvehicle.harness.ardupilot.driver import (
    COPTER_MODE_GUIDED,
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_DO_SET_MODE,
    MAV_CMD_NAV_TAKEOFF,
    DriverInputs,
    FlightDriver,
)
from simvehicle.harness.ardupilot.gnss_source import gps_input_fields
from simvehicle.harness.ardupilot.session import ArduPilotSession
from simvehicle.harness.fly import planned_route
from simvehicle.harness.foreign.analysis import autopilot_track, companion_track, count_collisions, errors
from simvehicle.harness.foreign.gnss_source import UrbanGnssSource
from simvehicle.harness.foreign.recording import Recording


def _line(t_us: np.ndarray) -> np.ndarray:
    """A straight pass along the test city's cross street (north 52 m), 3 m/s east."""
    t = t_us * 1e-6
    return np.column_stack([np.full_like(t, 52.0), 5.0 + 3.0 * t, np.full_like(t, -15.0)])


def test_source_is_our_model_sampled_on_the_truth_stream():
    """Driven by 50 Hz truth, the source makes exactly the fixes GnssModel makes when stepped at the
    same validity times (one per 100 ms), and releases each once its modelled latency has elapsed."""
    m = load_mission("test")
    cfg = GnssConfig()
    t_us = np.arange(0, 20_000_000, 20_000)  # 50 Hz truth
    p = _line(t_us)
    d0 = float(m.world.clearance_m(p[0, 0], p[0, 1]))
    src = UrbanGnssSource(cfg, m.world, m.frame, 10.0, np.random.default_rng(7), d0)
    ref = GnssModel(cfg, 0.1, m.frame, np.random.default_rng(7), d0)
    expected = []
    for t, pk in zip(t_us.tolist(), p, strict=True):
        src.on_truth(t, pk)
        src.due(t)
        if t % 100_000 == 0:
            expected.append(ref.sample(t, pk, float(m.world.clearance_m(pk[0], pk[1]))))
    sent = sorted(src.sent, key=lambda s: s.fix.t_validity_us)
    assert len(expected) == 200 and len(sent) >= 195  # the last few are still in flight
    for sf, nf in zip(sent, expected, strict=False):
        assert sf.fix.t_validity_us == nf.t_validity_us
        np.testing.assert_array_equal(sf.p_ned_m, nf.p_ned_m)
        assert sf.arrival_us >= sf.fix.t_validity_us  # never early
        assert sf.arrival_us - sf.fix.t_validity_us <= cfg.latency_cap_s * 1e6 + 20_000  # <= cap + 1 tick
    lat = np.array([s.arrival_us - s.fix.t_validity_us for s in sent]) * 1e-6
    assert lat.max() > 0.3  # the canyon's latency shows (street between buildings)
    # the geodetic wire form is the NED fix in the mission frame (to 1 mm)
    back = m.frame.to_ned_m(sent[50].fix.lat_deg, sent[50].fix.lon_deg, sent[50].fix.alt_m)
    np.testing.assert_allclose(back, sent[50].p_ned_m, atol=1e-3)


def test_gps_input_fields_pack_and_mean_what_they_say():
    m = load_mission("test")
    src = UrbanGnssSource(GnssConfig(), m.world, m.frame, 10.0, np.random.default_rng(1), 20.0)
    src.on_truth(1_234_567, np.array([10.0, 10.0, -15.0]))
    (sf,) = src.due(10_000_000)
    f = gps_input_fields(sf)
    assert f["gps_id"] == 0  # GPS1 (open loop)
    assert f["time_week_ms"] == 1234 and f["time_usec"] == 1_234_567  # validity time, not arrival
    assert f["lat"] == round(sf.fix.lat_deg * 1e7) and f["lon"] == round(sf.fix.lon_deg * 1e7)
    assert f["fix_type"] == 3 and f["horiz_accuracy"] == pytest.approx(sf.fix.h_acc_m)
    assert f["ignore_flags"] == (mavlink.GPS_INPUT_IGNORE_FLAG_VEL_HORIZ
                                 | mavlink.GPS_INPUT_IGNORE_FLAG_VEL_VERT
                                 | mavlink.GPS_INPUT_IGNORE_FLAG_SPEED_ACCURACY)
    link = new_link(255, 190)
    frame = pack(link, mavlink.MAVLink_gps_input_message(**f))
    msg = mavlink.MAVLink(None).decode(bytearray(frame))
    assert msg.get_type() == "GPS_INPUT" and msg.lat == f["lat"] and msg.time_week == f["time_week"]


def test_parameters_make_gps_input_the_only_gnss_position_only():
    p = ardupilot_parameters(ArduPilotConfig(gps_delay_ms=120, gnss_velocity=False))
    assert p == {"GPS1_TYPE": 14, "GPS1_DELAY_MS": 120, "EK3_SRC1_VELXY": 0, "EK3_SRC1_VELZ": 0}
    with pytest.raises(ValueError, match="gnss_rate_hz"):
        ArduPilotConfig(gnss_rate_hz=50).validate()


def test_parameters_of_velocity_and_of_each_closed_loop():
    cfg = ArduPilotConfig(gps_delay_ms=100)
    assert ardupilot_parameters(cfg) == {"GPS1_TYPE": 14, "GPS1_DELAY_MS": 100, "EK3_SRC1_VELXY": 3,
                                         "EK3_SRC1_VELZ": 3}
    second = {"GPS2_TYPE": 14, "GPS2_DELAY_MS": 100, "GPS_AUTO_SWITCH": 0}
    gi = ardupilot_parameters(cfg, "gps-input")
    assert gi == {"GPS1_TYPE": 14, "GPS1_DELAY_MS": 1, **second, "GPS_PRIMARY": 0}
    vision = ardupilot_parameters(cfg, "vision")
    assert vision["GPS1_TYPE"] == 0 and vision["GPS_PRIMARY"] == 1 and vision["EK3_SRC1_POSXY"] == 6
    assert vision["VISO_TYPE"] == 1 and vision["EK3_SRC1_VELXY"] == 0 and vision["EK3_SRC1_POSZ"] == 1
    assert all(vision[k] == v for k, v in second.items())


def test_velocity_is_truth_plus_the_stated_noise_and_leaves_the_positions_alone():
    """With a Doppler velocity the fixes' positions are the same draws as without; the velocity of
    each fix is the truth at its validity time plus N(0, σ) (σ from 2000 fixes within 10 %)."""
    m = load_mission("test")
    t_us = np.arange(0, 200_000_000, 20_000)
    p = _line(t_us)
    v_true = np.array([0.0, 3.0, 0.0])
    d0 = float(m.world.clearance_m(p[0, 0], p[0, 1]))
    plain = UrbanGnssSource(GnssConfig(), m.world, m.frame, 10.0, np.random.default_rng(3), d0)
    vel = UrbanGnssSource(GnssConfig(), m.world, m.frame, 10.0, np.random.default_rng(3), d0, 0.1,
                          np.random.default_rng([3, 1]))
    for t, pk in zip(t_us.tolist(), p, strict=True):
        for src in (plain, vel):
            src.on_truth(t, pk, v_true)
            src.due(t)
    assert len(plain.sent) == len(vel.sent) > 1900
    for a, b in zip(plain.sent, vel.sent, strict=True):
        np.testing.assert_array_equal(a.p_ned_m, b.p_ned_m)
        assert a.v_ned_m_s is None
    v = np.array([sf.v_ned_m_s for sf in vel.sent])
    noise = v - v_true
    assert abs(noise.mean()) < 0.01 and 0.09 < noise.std() < 0.11
    f = gps_input_fields(vel.sent[0], gps_id=1, velocity_sigma_m_s=0.1)
    assert f["gps_id"] == 1 and f["ignore_flags"] == 0 and f["speed_accuracy"] == pytest.approx(0.1)
    assert (f["vn"], f["ve"], f["vd"]) == pytest.approx(tuple(v[0]))
    # what the companion is given in the analysis: the same velocity with the speed accuracy GPS_INPUT says
    assert all(sf.speed_accuracy_m_s == 0.1 for sf in vel.sent)
    assert math.isnan(plain.sent[0].speed_accuracy_m_s)
    with pytest.raises(ValueError, match="generator"):
        UrbanGnssSource(GnssConfig(), m.world, m.frame, 10.0, np.random.default_rng(3), d0, 0.1)


def test_driver_guided_arm_takeoff_then_the_route_in_the_autopilots_frame():
    m = load_mission("test")
    route = planned_route(m, 2, 0.0)
    cfg = ArduPilotConfig()
    drv = FlightDriver(cfg, route, m.altitude_m)
    now = DriverInputs(t_us=1_000_000)
    assert drv.step(now) == []  # EKF3 has no position yet: nothing asked
    now.ekf_position_ok = True
    (c,) = drv.step(now)
    assert c.args[:3] == (MAV_CMD_DO_SET_MODE, 1, COPTER_MODE_GUIDED)
    now.t_us += 100_000
    assert drv.step(now) == []  # retried once a second only
    now.mode = COPTER_MODE_GUIDED
    (c,) = drv.step(now)
    assert drv.phase == "arm" and c.args[:2] == (MAV_CMD_COMPONENT_ARM_DISARM, 1)
    now.armed, now.t_us = True, now.t_us + 1_000_000
    (c,) = drv.step(now)
    assert drv.phase == "takeoff" and c.args[0] == MAV_CMD_NAV_TAKEOFF and c.args[7] == m.altitude_m
    now.takeoff_accepted, now.t_us = True, now.t_us + 2_000_000
    assert drv.step(now) == []  # accepted: not sent again
    origin = np.array([52.3, 4.6, -0.4])
    now.origin_ned_m = origin
    # EKF3's AMSL height off by more than the tolerance (the origin fix's vertical error): the
    # take-off is judged on its height above home
    now.ekf_ned_m = np.array([52.0, 5.0, -m.altitude_m - 3.0])
    now.ekf_height_m = m.altitude_m - 2.0
    assert drv.step(now) == [] and drv.phase == "takeoff"  # below: still climbing
    now.ekf_height_m = m.altitude_m - 0.5
    assert drv.step(now) == []  # at altitude: hover first
    now.t_us += round(cfg.hover_before_route_s * 1e6)
    (c,) = drv.step(now)
    assert drv.phase == "route" and c.kind == "setpoint" and drv.route_t0_us == now.t_us
    p0, v0, a0 = route.reference(0.0)
    np.testing.assert_allclose(c.args[1:4], p0 - origin)  # mission NED -> ArduPilot local NED
    np.testing.assert_allclose(c.args[4:7], v0)
    now.t_us += 10_000
    assert drv.step(now) == []  # 20 Hz
    now.t_us += 40_000
    (c,) = drv.step(now)
    np.testing.assert_allclose(c.args[1:4], route.reference(0.05)[0] - origin)
    goal = route.waypoints_ned_m[-1]
    now.truth_ned_m, now.truth_v_ned_m_s = goal + 0.5, np.zeros(3)
    drv.step(now)
    assert drv.phase == "route"  # at the goal before the reference arrived: not done
    now.t_us = drv.route_t0_us + round(route.duration_s * 1e6) + 1
    assert drv.step(now) == [] and drv.outcome == "reached_goal"


def test_session_places_ekf3s_local_frame_by_its_origin_and_its_ground_height(tmp_path):
    """The flight whose tracking error was 189 m (canyon, profile 4, seed 0): EKF3's origin was set
    from a fix 21.4 m too high, its barometric altitude on the ground said 428.12 m (home 408 m), and
    the route's setpoints, placed by the origin's altitude, were 1.3 m BELOW the ground: the vehicle
    descended into it. Vertically the local frame is now placed by EKF3's height on the ground before
    arming (the mission's ground), so a setpoint at the mission altitude is that far above it in
    EKF3's local z; horizontally by the origin, as before."""
    m = load_mission("test")
    route = planned_route(m, 2, 0.0)
    drv = FlightDriver(ArduPilotConfig(), route, m.altitude_m)
    source = UrbanGnssSource(GnssConfig(), m.world, m.frame, 10.0, np.random.default_rng(0), 20.0)
    s = ArduPilotSession(1, ArduPilotConfig(), m.frame, source, drv, tmp_path / "x.tlog")
    home_alt = float(m.frame.to_geodetic(np.zeros(3))[2])
    lat, lon, alt = m.frame.to_geodetic(np.array([10.0, -4.0, -21.4]))  # the origin's fix: 21.4 m high

    def gpi(alt_m: float, relative_alt_m: float, t_ms: int, position: bool = True) -> types.SimpleNamespace:
        return types.SimpleNamespace(lat=round(lat * 1e7) if position else 0,
                                     lon=round(lon * 1e7) if position else 0,
                                     alt=round(alt_m * 1e3), relative_alt=round(relative_alt_m * 1e3),
                                     time_boot_ms=t_ms)

    s._handle_vehicle("GLOBAL_POSITION_INT", gpi(0.0, 0.0, 500, position=False))  # no position yet
    s._handle_vehicle("GPS_GLOBAL_ORIGIN", types.SimpleNamespace(latitude=round(lat * 1e7),
                                                                 longitude=round(lon * 1e7),
                                                                 altitude=round(alt * 1e3)))
    assert s.ground_alt_m is None and s.now.origin_ned_m is None  # no ground height yet: nothing placed
    s._handle_vehicle("GLOBAL_POSITION_INT", gpi(home_alt + 20.12, 0.0, 1000))  # on the ground, disarmed
    ground_z_local = alt - (home_alt + 20.12)  # EKF3's local z on the ground: 1.28 m below its origin
    np.testing.assert_allclose(s.now.origin_ned_m, [10.0, -4.0, -ground_z_local], atol=0.02)
    s._handle_vehicle("HEARTBEAT", types.SimpleNamespace(custom_mode=COPTER_MODE_GUIDED, base_mode=128 | 1))
    s._handle_vehicle("GLOBAL_POSITION_INT", gpi(home_alt + 40.1, 20.0, 2000))  # armed, at 20 m
    assert s.ground_alt_m == pytest.approx(home_alt + 20.12)  # armed: the ground is no longer taken
    # a setpoint at the mission altitude over the origin: EKF3's local z of 20 m above the ground
    drv.route_t0_us = 0
    (c,) = drv.setpoint(DriverInputs(t_us=3_000_000, origin_ned_m=s.now.origin_ned_m),
                        np.array([10.0, -4.0, -m.altitude_m]))
    np.testing.assert_allclose(c.args[1:4], [0.0, 0.0, ground_z_local - m.altitude_m], atol=0.02)
    s.close()


def test_driver_back_to_arming_when_disarmed_and_timeout():
    m = load_mission("test")
    route = planned_route(m, 2, 0.0)
    drv = FlightDriver(ArduPilotConfig(), route, m.altitude_m)
    drv.phase = "takeoff"
    assert drv.step(DriverInputs(t_us=5_000_000, armed=False, ekf_position_ok=True)) == []
    assert drv.phase == "arm"
    drv.phase, drv.route_t0_us = "route", 0
    drv.step(DriverInputs(t_us=int(drv.route_end_us) + 1, origin_ned_m=np.zeros(3)))
    assert drv.outcome == "timeout"


def test_companion_track_is_the_navigators_batch_path_sample_by_sample():
    """The scoring pushes each recorded IMU sample as an attitude and a specific force: the same bits as
    ``Navigator.push_imu_batch`` of that one sample (its documented equivalence), for every method's
    estimate at every evaluation time, with fixes released between samples."""
    from companion.estimator import EstimatorConfig
    from companion.wiring import navigator_for
    from simvehicle.harness.foreign import analysis

    m = load_mission("test")
    t_us = np.arange(0, 12_000_000, 20_000)  # 50 Hz
    p = _line(t_us)
    src = UrbanGnssSource(GnssConfig(), m.world, m.frame, 10.0, np.random.default_rng(3),
                          float(m.world.clearance_m(p[0, 0], p[0, 1])))
    rng = np.random.default_rng(4)
    rec = Recording()
    for t, pk in zip(t_us.tolist(), p, strict=True):
        src.on_truth(t, pk)
        src.due(t)
        q = np.array([1.0, 0.0, 0.0, 0.0]) + rng.normal(0.0, 0.01, 4)
        rec.imu_t_us.append(t)
        rec.imu_acc_frd_m_s2.append(np.array([0.0, 0.0, -9.81]) + rng.normal(0.0, 0.05, 3))
        rec.imu_q_ned_frd.append(q / np.linalg.norm(q))
    times = t_us[100:]  # the evaluation times: from 2 s on (before them, no estimate is asked)
    sent = src.sent
    assert len(sent) > 100
    for method in ("second-order", "vbakf", "hmm-trust"):
        got = companion_track(rec, sent, method, EstimatorConfig(), m, times)
        nav = navigator_for(m, method, config=EstimatorConfig())

        def batch_of_one(t: int, f: np.ndarray, q: np.ndarray, nav=nav) -> None:
            nav.push_imu_batch(np.array([t]), f[None, :], q[None, :])

        def push_fix(sf, nav=nav) -> None:
            nav.push_fix_ned(sf.fix.t_validity_us, sf.p_ned_m, sf.fix.h_acc_m, sf.fix.v_acc_m, sf.v_ned_m_s,
                             sf.speed_accuracy_m_s)

        arrivals = [(sf.arrival_us, sf) for sf in sent]
        ref = analysis._replayed(rec, arrivals, batch_of_one, push_fix, nav, times)
        assert np.isfinite(got.p_ned_m).all(), method
        for name in ("p_ned_m", "b_ned_m", "beta", "nis"):
            np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=f"{method} {name}")
        assert got.counters == ref.counters, method


def test_analysis_known_answers():
    assert count_collisions(np.array([5.0, 0.2, 0.1, 3.0, 0.25, 4.0]), 0.3) == 2
    assert count_collisions(np.array([0.1, 1.0]), 0.3) == 1
    rec = Recording()
    rec.ekf_t_us = [1_000_000, 0]  # out of order on purpose
    rec.ekf_p_ned_m = [np.array([10.0, 0.0, -5.0]), np.array([0.0, 0.0, -5.0])]
    tr = autopilot_track(rec, np.array([0, 250_000, 1_000_000, 1_500_000]))
    np.testing.assert_allclose(tr.p_ned_m[:3, 0], [0.0, 2.5, 10.0])
    assert np.isnan(tr.p_ned_m[3]).all()  # after its last sample: unknown, not extrapolated
    e3, eh = errors(np.array([[3.0, 4.0, 12.0]]), np.zeros((1, 3)))
    assert e3[0] == pytest.approx(13.0) and eh[0] == pytest.approx(5.0)
    assert math.isnan(errors(np.full((1, 3), np.nan), np.zeros((1, 3)))[0][0])


def test_campaign_aggregate_known_answers(tmp_path):
    from dataclasses import replace

    from gcs_tools.evaluate.ardupilot import CAMPAIGN as ARDUPILOT
    from gcs_tools.evaluate.autopilot import Job, Result, aggregate, table_text

    def result(seed: int, ekf: float, comp: float, error: str = "") -> Result:
        job = Job(ARDUPILOT, "test", 0, seed, ("second-order",), tmp_path, ArduPilotConfig())
        errs = {} if error else {"ardupilot-ekf3": np.full(10, ekf), "second-order": np.full(10, comp)}
        return Result(job, errs, np.full(10, 1.0), not error, 0, "reached_goal", 10.0, 1.0, error)

    res = aggregate(ARDUPILOT, [result(0, 2.0, 1.0), result(1, 4.0, 1.0), result(2, 0, 0, "no SITL"),
                                replace(result(2, 9.0, 9.0), valid=False)],
                    ("ardupilot-ekf3", "second-order"), (0, 1, 2))
    ol = res["open_loop"]
    assert ol["ardupilot-ekf3"]["median"] == pytest.approx(3.0) and ol["ardupilot-ekf3"]["n"] == 20
    assert ol["second-order"]["reduction_vs_ekf3"] == pytest.approx(1.0 / 3.0 - 1.0)
    assert ol["second-order"]["flight_medians"] == [1.0, 1.0]
    # seed 2 was not flown: its medians are NaN and left out of the paired comparison
    assert ol["second-order"]["reduction_vs_ekf3_seeds"]["value"] == pytest.approx(1.0 / 3.0 - 1.0)
    # the late flight (commands delayed by the scheduler) is counted but not used
    assert res["flying"]["none"]["flights"] == 4 and res["flying"]["none"]["valid"] == 2
    assert "| second-order | 1.00 |" in table_text(ARDUPILOT, res)
    assert "ardupilot-ekf3-posonly" not in ol  # no such flights: no row


def test_campaign_rows_of_the_position_only_and_closed_loops(tmp_path):
    """EKF3 without velocity is its own open-loop row (paired with EKF3 by seed); closed loops add
    no open-loop row but report EKF3's error (what it flew on) and what the companion sent."""
    from gcs_tools.evaluate.ardupilot import CAMPAIGN as ARDUPILOT
    from gcs_tools.evaluate.autopilot import Job, Result, aggregate, table_text

    def result(seed: int, loop: str, errs: dict) -> Result:
        job = Job(ARDUPILOT, "test", 0, seed, ("second-order",), tmp_path, ArduPilotConfig(), loop)
        errs = {k: np.full(10, v) for k, v in errs.items()}
        # arrived with one contact: not a goal reached (as fly counts it), but it arrived
        return Result(job, errs, np.full(10, 2.0), False, 1, "reached_goal", 10.0, 1.0)

    results = [result(s, "none", {"ardupilot-ekf3": 2.0 + s, "second-order": 1.0}) for s in (0, 1)]
    results += [result(s, "none-posonly", {"ardupilot-ekf3-posonly": 4.0 + 2 * s}) for s in (0, 1)]
    results += [result(s, "vision", {"ardupilot-ekf3": 1.5, "companion-live": 1.25}) for s in (0, 1)]
    rows = ("ardupilot-ekf3", "ardupilot-ekf3-posonly", "second-order")
    res = aggregate(ARDUPILOT, results, rows, (0, 1))
    ol = res["open_loop"]
    assert list(ol) == list(rows) and ol["ardupilot-ekf3"]["median"] == pytest.approx(2.5)
    assert ol["ardupilot-ekf3-posonly"]["reduction_vs_ekf3"] == pytest.approx(5.0 / 2.5 - 1.0)
    v = res["flying"]["vision"]
    assert v["flights"] == 2 and v["collisions"] == 2 and v["reached_goal"] == 0 and v["arrived"] == 2
    assert v["flown_estimate_error_horizontal_m"]["median"] == pytest.approx(1.5)
    assert v["companion_sent_error_horizontal_m"]["median"] == pytest.approx(1.25)
    assert res["flying"]["none-posonly"]["flown_estimate_error_horizontal_m"]["median"] == pytest.approx(5.0)
    assert res["flying"]["none"]["companion_sent_error_horizontal_m"]["n"] == 0
    text = table_text(ARDUPILOT, res)
    assert "ExternalNav | 2 (2) | 0 (2) | 2 | 2.00 | 2.00 | 1.50 | 1.25 |" in text


def test_sitl_ardupilot_option_errors_are_one_line(tmp_path, capsys):
    from gcs_tools.cli import main

    assert main(["sitl", "--vehicle", "ardupilot", "--realtime", "--out", str(tmp_path)]) == 2
    assert "apply to --vehicle sim only" in capsys.readouterr().err
    assert main(["sitl", "--vehicle", "ardupilot", "--mission", "test", "--profile", "7",
                 "--out", str(tmp_path)]) == 2
    assert "profiles 0..2" in capsys.readouterr().err
    assert main(["sitl", "--vehicle", "ardupilot", "--gnss-rate-hz", "50", "--out", str(tmp_path)]) == 2
    assert "gnss_rate_hz" in capsys.readouterr().err


def test_evaluate_ardupilot_option_errors_are_one_line(tmp_path, capsys):
    from gcs_tools.cli import main

    assert main(["evaluate", "--vehicle", "ardupilot", "--max-duration-s", "5", "--out", str(tmp_path)]) == 2
    assert "--max-duration-s and --rows apply to --vehicle sim only" in capsys.readouterr().err
    for feeds in ("radar", "none,vision,none"):
        assert main(["evaluate", "--vehicle", "ardupilot", "--feeds", feeds, "--out", str(tmp_path)]) == 2
        assert "--feeds: expected distinct values of none, none-posonly, gps-input, vision" in \
            capsys.readouterr().err
