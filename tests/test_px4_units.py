"""Pure parts of the PX4 flight: parameters, HIL_GPS fields, the OFFBOARD driver, the placement of
EKF2's local frame, the launcher's files, the campaign's rows and the command-line errors."""

from __future__ import annotations

import types
from pathlib import Path

import numpy as np
import pytest

from companion.errors import UserError
from companion.mavlink.codec import mavlink, new_link, pack
from companion.mission import load_mission
from simvehicle.config import GnssConfig
from simvehicle.harness.fly import planned_route
from simvehicle.harness.foreign.driver import DriverInputs
from simvehicle.harness.foreign.gnss_source import UrbanGnssSource
from simvehicle.harness.px4.config import Px4FlightConfig, px4_parameters
from simvehicle.harness.px4.driver import ARM, SET_OFFBOARD, OffboardDriver, main_mode
from simvehicle.harness.px4.session import Px4Session, hil_gps_fields
from simvehicle.harness.px4.sitl import Px4Config, Px4Sitl, _param_lines, instance_ports

OFFBOARD_MODE = 6 << 16  # HEARTBEAT custom_mode of PX4's OFFBOARD (main mode 6)


def test_parameters_make_hil_gps_the_only_gnss_and_odometry_external_vision():
    common = {"SENS_EN_GPSSIM": 0, "MAV_USEHILGPS": 1, "EKF2_GPS_DELAY": 100}
    assert px4_parameters(Px4FlightConfig()) == {**common, "EKF2_GPS_CTRL": 7}
    assert px4_parameters(Px4FlightConfig(gnss_velocity=False)) == {**common, "EKF2_GPS_CTRL": 3}
    closed = px4_parameters(Px4FlightConfig(), "odometry")
    assert closed == {**common, "EKF2_GPS_CTRL": 0, "EKF2_EV_CTRL": 11, "EKF2_EV_NOISE_MD": 0,
                      "EKF2_HGT_REF": 3}
    for bad, match in ((dict(speed_factor=20.0), "speed_factor"), (dict(gnss_rate_hz=50.0), "gnss_rate_hz"),
                       (dict(gps_delay_ms=-5), "gps_delay_ms"),
                       (dict(setpoint_rate_hz=0.0), "setpoint_rate_hz")):
        with pytest.raises(ValueError, match=match):
            Px4FlightConfig(**bad).validate()


def test_hil_gps_fields_are_what_px4_reads_and_pack():
    m = load_mission("test")
    src = UrbanGnssSource(GnssConfig(), m.world, m.frame, 10.0, np.random.default_rng(1), 20.0, 0.1,
                          np.random.default_rng([1, 1]))
    src.on_truth(2_345_678, np.array([10.0, 10.0, -15.0]), np.array([3.0, -4.0, 0.5]))
    (sf,) = src.due(10_000_000)
    f = hil_gps_fields(sf)
    assert f["time_usec"] == 2_345_678 and f["fix_type"] == 3  # the validity time, kept as PX4's UTC stamp
    assert f["lat"] == round(sf.fix.lat_deg * 1e7) and f["alt"] == round(sf.fix.alt_m * 1000)
    # PX4 reads eph/epv as cm: the reported accuracy (the model's white-noise std), at least 1 cm
    assert f["eph"] == max(round(100 * sf.fix.h_acc_m), 1)
    v = sf.v_ned_m_s
    assert (f["vn"], f["ve"], f["vd"]) == tuple(round(100 * x) for x in v)
    assert f["vel"] == round(100 * np.hypot(v[0], v[1]))
    assert f["cog"] == round(100 * np.degrees(np.arctan2(v[1], v[0]))) % 36000  # course over ground, cdeg
    assert 0 <= f["cog"] < 36000 and f["satellites_visible"] == sf.fix.satellites_visible
    frame = pack(new_link(1, 190), mavlink.MAVLink_hil_gps_message(**f))
    msg = mavlink.MAVLink(None).decode(bytearray(frame))
    assert msg.get_type() == "HIL_GPS" and msg.get_srcSystem() == 1 and msg.eph == f["eph"]
    plain = UrbanGnssSource(GnssConfig(), m.world, m.frame, 10.0, np.random.default_rng(1), 20.0)
    plain.on_truth(0, np.zeros(3))
    (no_velocity,) = plain.due(10_000_000)
    g = hil_gps_fields(no_velocity)
    assert (g["vel"], g["vn"], g["cog"]) == (0, 0, 65535)  # zeros, course unknown


def _driver() -> tuple[OffboardDriver, object, float]:
    m = load_mission("test")
    route = planned_route(m, 2, 0.0)
    return OffboardDriver(Px4FlightConfig(), route, m.altitude_m, warmup_s=1.0), route, m.altitude_m


def test_offboard_driver_streams_setpoints_then_offboard_arm_climb_route():
    drv, route, altitude = _driver()
    origin = np.array([0.5, -0.8, -0.2])  # PX4's local origin in the mission frame
    now = DriverInputs(t_us=1_000_000)
    assert drv.step(now) == [] and drv.phase == "wait"  # EKF2 has no position yet
    now.ekf_position_ok, now.origin_ned_m = True, origin
    (sp,) = drv.step(now)
    climb = np.array(route.reference(0.0)[0]) * [1, 1, 0] + [0, 0, -altitude]
    assert drv.phase == "offboard" and sp.kind == "setpoint"
    np.testing.assert_allclose(sp.args[1:4], climb - origin)  # the route's start at altitude, local frame
    now.t_us += 500_000
    assert [c.kind for c in drv.step(now)] == ["setpoint"]  # warming up: setpoints only
    now.t_us += 600_000
    assert [c.args for c in drv.step(now) if c.kind == "command_long"] == [SET_OFFBOARD]
    now.t_us += 100_000
    assert not [c for c in drv.step(now) if c.kind == "command_long"]  # once a second
    now.mode = OFFBOARD_MODE
    now.t_us += 50_000
    cmds = drv.step(now)
    assert drv.phase == "arm" and [c.args for c in cmds if c.kind == "command_long"] == [ARM]
    now.armed, now.t_us = True, now.t_us + 50_000
    drv.step(now)
    assert drv.phase == "climb"
    now.mode, now.t_us = 4 << 16 | 3 << 24, now.t_us + 50_000  # a failsafe left OFFBOARD (AUTO.LOITER)
    drv.step(now)
    assert drv.phase == "offboard"
    now.mode = OFFBOARD_MODE
    drv.step(now)
    drv.step(now)
    assert drv.phase == "climb"
    now.ekf_height_m = altitude - 0.5
    now.t_us += 50_000
    drv.step(now)  # at altitude: hover first
    now.t_us += round(3.0e6)
    (sp,) = drv.step(now)
    assert drv.phase == "route" and drv.route_t0_us == now.t_us
    np.testing.assert_allclose(sp.args[1:4], route.reference(0.0)[0] - origin)


def test_main_mode_of_px4_custom_mode():
    assert main_mode(393216) == 6 and main_mode(50593792) == 4 and main_mode(None) is None


def test_session_places_ekf2s_local_frame_by_its_origin_and_its_ground_height(tmp_path):
    """Horizontal: EKF2's origin (GPS_GLOBAL_ORIGIN) in the mission frame; vertical: EKF2's z on the
    ground before arming is the mission's ground, whatever EKF2 thinks its altitude is (with an
    origin set over MAVLink it moved its local z by the origin's altitude: +489 m measured)."""
    m = load_mission("test")
    drv, _, _ = _driver()
    source = UrbanGnssSource(GnssConfig(), m.world, m.frame, 10.0, np.random.default_rng(0), 20.0)
    s = Px4Session("udpout:127.0.0.1:1", 1, Px4FlightConfig(), m.frame, source, drv, tmp_path / "x.tlog")
    lat, lon, alt = m.frame.to_geodetic(np.array([10.0, -4.0, -2.0]))

    def local(x: float, y: float, z: float, t_ms: int) -> types.SimpleNamespace:
        return types.SimpleNamespace(x=x, y=y, z=z, time_boot_ms=t_ms)

    s._handle_vehicle("LOCAL_POSITION_NED", local(0.3, 0.1, 489.4, 1000))
    assert s.now.origin_ned_m is None and not s.rec.ekf_t_us  # no origin yet: nothing placed
    s._handle_vehicle("GPS_GLOBAL_ORIGIN", types.SimpleNamespace(latitude=round(lat * 1e7),
                                                                 longitude=round(lon * 1e7),
                                                                 altitude=round(alt * 1e3)))
    np.testing.assert_allclose(s.now.origin_ned_m, [10.0, -4.0, -489.4], atol=0.02)
    s._handle_vehicle("HEARTBEAT", types.SimpleNamespace(custom_mode=OFFBOARD_MODE, base_mode=128 | 1))
    s._handle_vehicle("LOCAL_POSITION_NED", local(5.0, 2.0, 489.4 - 15.0, 2000))
    assert s.ground_z_m == pytest.approx(489.4)  # armed: the ground is no longer taken
    np.testing.assert_allclose(s.now.ekf_ned_m, [15.0, -2.0, -15.0], atol=0.02)
    assert s.now.ekf_height_m == pytest.approx(15.0) and s.rec.ekf_t_us == [2_000_000]
    s._handle_vehicle("LOCAL_POSITION_NED", local(float("nan"), 0.0, 0.0, 3000))
    assert s.rec.rejected == {"local_position_non_finite": 1}
    s.close()


def test_launcher_files_ports_and_a_missing_build(tmp_path):
    assert instance_ports(0) == (14540, 14580, 18570, 14280, 13030, 19450)
    assert instance_ports(3) == (14543, 14583, 18573, 14283, 13033, 19453)
    text = _param_lines({"EKF2_GPS_CTRL": 7, "EKF2_GPS_DELAY": 100.0, "EKF2_EVP_NOISE": 0.25}, logging=False)
    assert text.splitlines()[2:] == ["param set SDLOG_MODE -1", "param set EKF2_GPS_CTRL 7",
                                     "param set EKF2_GPS_DELAY 100", "param set EKF2_EVP_NOISE 0.25"]
    assert "SDLOG_MODE" not in _param_lines({}, logging=True)
    with pytest.raises(UserError, match="bad PX4 parameter name"):
        _param_lines({"ekf2_gps_ctrl": 1}, logging=False)
    with pytest.raises(UserError, match="must be finite"):
        _param_lines({"EKF2_GPS_CTRL": float("nan")}, logging=False)
    with pytest.raises(UserError, match="PX4 SITL not found"):
        Px4Sitl(Px4Config(work_dir=tmp_path / "w", px4_dir=tmp_path / "nowhere"))


def test_campaign_rows_of_px4_loops(tmp_path):
    """EKF2 with and without the Doppler velocity are open-loop rows, the companion's reduction is
    taken against EKF2 (``reduction_vs_ekf2``); the closed loop reports what PX4 flew on and what the
    companion sent."""
    from gcs_tools.evaluate.autopilot import Job, Result, aggregate, table_text
    from gcs_tools.evaluate.px4 import CAMPAIGN

    def result(seed: int, loop: str, errs: dict, collisions: int = 0) -> Result:
        job = Job(CAMPAIGN, "test", 0, seed, ("second-order",), tmp_path, Px4FlightConfig(), loop)
        return Result(job, {k: np.full(10, v) for k, v in errs.items()}, np.full(10, 2.0), True, collisions,
                      "reached_goal", 10.0, 1.0)

    results = [result(s, "none", {"px4-ekf2": 2.0 + s, "second-order": 1.0}, collisions=1) for s in (0, 1)]
    results += [result(s, "none-posonly", {"px4-ekf2-posonly": 4.0}) for s in (0, 1)]
    results += [result(s, "odometry", {"px4-ekf2": 1.5, "companion-live": 1.25}) for s in (0, 1)]
    res = aggregate(CAMPAIGN, results, ("px4-ekf2", "px4-ekf2-posonly", "second-order"), (0, 1))
    ol = res["open_loop"]
    assert ol["px4-ekf2"]["median"] == pytest.approx(2.5)
    assert ol["second-order"]["reduction_vs_ekf2"] == pytest.approx(1.0 / 2.5 - 1.0)
    assert ol["px4-ekf2-posonly"]["reduction_vs_ekf2_seeds"]["value"] == pytest.approx(4.0 / 2.5 - 1.0)
    assert res["flying"]["none"]["collisions"] == 2 and res["flying"]["odometry"]["collisions"] == 0
    assert res["flying"]["odometry"]["companion_sent_error_horizontal_m"]["median"] == pytest.approx(1.25)
    text = table_text(CAMPAIGN, res)
    assert "| PX4 flies on |" in text
    assert "| EKF2 on second-order's ODOMETRY (external vision) | 2 (2) |" in text


@pytest.mark.parametrize("argv, message", [
    (["sitl", "--vehicle", "px4", "--speedup", "5"], "--speedup applies to --vehicle ardupilot only"),
    (["sitl", "--vehicle", "ardupilot", "--speed-factor", "5"],
     "--speed-factor applies to --vehicle px4 only"),
    (["sitl", "--vehicle", "ardupilot", "--ulog"], "--ulog applies to --vehicle px4 only"),
    (["sitl", "--vehicle", "px4", "--feed", "gps-input"],
     "--feed gps-input: with --vehicle px4, --feed is one of none, odometry"),
    (["sitl", "--vehicle", "px4", "--speed-factor", "20"], "px4: speed_factor: within (0, 10]"),
    (["sitl", "--vehicle", "px4", "--mission", "test", "--profile", "7"], "profiles 0..2"),
    (["sitl", "--feed", "odometry"], "apply to --vehicle ardupilot or px4"),
    (["evaluate", "--vehicle", "px4", "--feeds", "vision"],
     "--feeds: expected distinct values of none, none-posonly, odometry"),
    (["evaluate", "--vehicle", "px4", "--speedup", "3"], "--speedup applies to --vehicle ardupilot only"),
    (["evaluate", "--feeds", "none"], "apply to --vehicle ardupilot or px4"),
    (["evaluate", "--resume"], "apply to --vehicle ardupilot or px4"),
])
def test_px4_option_errors_are_one_line(tmp_path: Path, capsys, argv, message):
    from gcs_tools.cli import main

    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
