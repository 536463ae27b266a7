"""``beliefnav companion`` beside a real PX4 SITL (SIH quadrotor, x5, one instance for the module):
discovery, stream requests, PX4's TIMESYNC on the boot time, the EKF origin, a reboot, and EKF2
fusing ODOMETRY as external vision, checked in its own uORB topics (``px4-listener``)."""

from __future__ import annotations

import json
import struct
import time

import numpy as np
import pytest
from ardupilot_helpers import interrupt_when, run_companion, stop, tlog_messages, wait_or_dump
from px4_helpers import TEST_INSTANCES, GroundStation, listener, px4_fixture
from pymavlink.dialects.v20 import common as M  # noqa: N812 - as mavutil.mavlink

from companion.autopilot.feeds import covariance21

HOME = (47.397742, 8.545594, 488.0)  # SIH's origin (PX4_HOME_LAT/LON/ALT)
EV_PARAMS = {"MAV_USEHILGPS": 1, "SENS_EN_GPSSIM": 0, "EKF2_GPS_CTRL": 0, "EKF2_EV_CTRL": 15,
             "EKF2_HGT_REF": 3, "EKF2_GPS_DELAY": 80}
px4 = px4_fixture(params=EV_PARAMS, home=HOME, instance_range=TEST_INSTANCES)


def _number(text: str) -> float:
    """The first number of a listener value ("0.25000", "[0.25000, 0.25000]", "True")."""
    text = text.strip("[]").split(",")[0].split()[0]
    return {"True": 1.0, "False": 0.0}[text] if text in ("True", "False") else float(text)


def test_companion_beside_px4_discovers_streams_keeps_its_clock_and_feeds_ekf2(px4, tmp_path):
    """PX4 fuses no GNSS here (EKF2_GPS_CTRL 0); the ground station sends HIL_GPS at SIH's truth, which
    PX4 streams to the companion as GPS_RAW_INT; the companion sets the EKF origin to --home and feeds
    ODOMETRY, which EKF2 fuses as external vision: its only source of position. Then PX4 reboots; the
    run ends with Ctrl-C (a clean end, exit 0) once the companion's summary has what is checked of it."""
    out = tmp_path / "companion"
    home = ",".join(f"{v:.7f}" for v in HOME)
    with GroundStation(px4).feed_gps():
        proc = run_companion(px4.url, out, "--feed", "odometry", "--home", home, "--duration-s", "40")
        try:
            fused: set[str] = set()  # EKF2's control-status flags seen set while we poll
            deadline = time.monotonic() + 15
            while time.monotonic() < deadline and not {"cs_ev_pos", "cs_ev_vel", "cs_ev_hgt"} <= fused:
                time.sleep(0.5)
                fused |= {k for k, v in listener(px4, "estimator_status_flags").items() if v == "True"}
            sync = listener(px4, "timesync_status")
            odometry = listener(px4, "vehicle_visual_odometry")
            local = listener(px4, "vehicle_local_position")
            time.sleep(3.0)  # (a reboot within 2 s of its stream requests is not asked again: by design)
            before = json.loads((out / "summary.json").read_text())["samples"]["received"]["HIGHRES_IMU"]
            px4.restart(wait_heartbeat=False)  # the companion holds the onboard port
            interrupt_when(proc, out, lambda s: _after_reboot(s, before), 25.0)
            wait_or_dump(proc, 30.0)
        finally:
            code, err = stop(proc)
    assert code == 0, err
    # EKF2 fuses our ODOMETRY (horizontal and vertical position, velocity; yaw too, against the
    # magnetometer now and then) and no GNSS
    assert {"cs_ev_pos", "cs_ev_vel", "cs_ev_hgt"} <= fused and "cs_gps" not in fused, fused
    # PX4 maps our stamps with the offset it derives from our TIMESYNC answers (once 500 quick ones have
    # arrived): we answer on its boot time (tc1 = ts1), so each offset it observes is exactly half the
    # round trip (answered with the host's clock it was minus the host's uptime, and every ODOMETRY
    # stamp was thrown to about 2^64 µs)
    assert abs(_number(sync["observed_offset"]) - _number(sync["round_trip_time"]) / 2) <= 1, sync
    t_sample, t_arrival = (_number(odometry[k].split()[0]) for k in ("timestamp_sample", "timestamp"))
    assert abs(t_arrival - t_sample) < 100_000, odometry  # within 0.1 s of arrival, on PX4's boot time

    s = json.loads((out / "summary.json").read_text())
    ap = s["autopilot"]
    assert (ap["system_id"], ap["component_id"], ap["autopilot"], ap["vehicle"]) == \
        (px4.system_id, 1, "MAV_AUTOPILOT_PX4", "MAV_TYPE_QUADROTOR")
    asks = s["streams"]["requests"]
    assert asks >= 2 and s["node"]["autopilot_reboots"] == 1  # asked again after the reboot
    assert s["streams"]["acks"]["MAV_CMD_SET_MESSAGE_INTERVAL:MAV_RESULT_ACCEPTED"] >= 8 * (asks - 1)
    assert s["gnss_delay"] == {"ms": 80.0, "source": "autopilot parameter EKF2_GPS_DELAY"}
    assert s["samples"]["used"]["imu"] > 2000 and s["samples"]["used"]["gnss"] > 200
    assert s["home"]["source"] == "option --home" and s["node"]["set_gps_global_origin_sent"] >= 1
    origin = s["autopilot_origins"]["GPS_GLOBAL_ORIGIN"]  # PX4's EKF origin is the one we set
    assert (round(origin["lat_deg"] * 1e7), round(origin["lon_deg"] * 1e7)) == \
        (round(HOME[0] * 1e7), round(HOME[1] * 1e7))
    # EKF2's local position is our ODOMETRY's (its only position source), on the ground
    ours = np.array([_number(odometry["position"].split(",")[i].strip(" []")) for i in range(2)])
    theirs_xy = np.array([_number(local["x"]), _number(local["y"])])
    assert local["xy_valid"] == "True" and np.hypot(*(ours - theirs_xy)) < 0.3, (odometry, local)
    assert s["node"]["feed_odometry_sent"] > 100

    msgs = tlog_messages(out / "run.tlog")
    theirs = [m for m in msgs if (m.get_srcSystem(), m.get_srcComponent()) == (px4.system_id, 1)]
    ours = [m for m in msgs if (m.get_srcSystem(), m.get_srcComponent()) == (px4.system_id, 197)]
    # PX4 asks for the time itself, at 10 Hz of its clock; each request is answered with its own time
    requests = [m.ts1 for m in theirs if m.get_type() == "TIMESYNC" and m.tc1 == 0]
    steps_ms = np.diff(requests) / 1e6
    assert len(requests) > 50 and np.median(steps_ms[steps_ms > 0]) == pytest.approx(100.0, abs=5)
    answers = {m.ts1: m.tc1 for m in ours if m.get_type() == "TIMESYNC" and m.tc1 > 0}
    # answered from discovery on (before PX4 is elected, a few seconds of its time, nothing is sent)
    first = next(i for i, t in enumerate(requests) if t in answers)
    assert first < len(requests) / 4 and all(t in answers for t in requests[first:] if t < requests[-1] - 1e9)
    assert answers and all(tc1 == ts1 for ts1, tc1 in answers.items())
    asked = {int(m.param1): m.param2 for m in ours if m.get_type() == "COMMAND_LONG"
             and m.command == M.MAV_CMD_SET_MESSAGE_INTERVAL}
    assert asked[M.MAVLINK_MSG_ID_HIGHRES_IMU] == 20_000
    imu = np.array([m.time_usec for m in theirs if m.get_type() == "HIGHRES_IMU"])
    reboot = int(np.argmax(np.diff(imu) < 0)) + 1
    assert reboot > 500 and imu.size - reboot > 100  # before and again after the reboot
    assert abs(np.median(np.diff(imu[:reboot])) - 20_000) < 2_000  # the 50 Hz asked for, PX4's clock


ACCEPTED = "MAV_CMD_SET_MESSAGE_INTERVAL:MAV_RESULT_ACCEPTED"


def _after_reboot(s: dict, imu_before: int) -> bool:
    """The streams asked for again after the reboot, accepted and arriving again; the counts checked
    reached with a margin."""
    asks, used = s["streams"]["requests"], s["samples"]["used"]
    return (s["node"]["autopilot_reboots"] == 1 and asks >= 2
            and s["streams"]["acks"].get(ACCEPTED, 0) >= 8 * (asks - 1)
            and s["samples"]["received"]["HIGHRES_IMU"] > imu_before + 300
            and used["imu"] > 2500 and used["gnss"] > 250)


def _set_int(gs: GroundStation, name: str, value: int) -> None:
    as_float = struct.unpack("<f", struct.pack("<i", value))[0]  # PX4 sends INT32 parameters bit-cast
    gs.send(M.MAVLink_param_set_message(gs.sitl.system_id, 1, name.encode(), as_float,
                                        M.MAV_PARAM_TYPE_INT32))


def _send_odometry(gs: GroundStation, seconds: float, estimator_type: int = M.MAV_ESTIMATOR_TYPE_VISION,
                   frame: int = M.MAV_FRAME_LOCAL_NED, variance: float = 0.25, quality: int = 100) -> None:
    """ODOMETRY at 30 Hz of PX4's time for ``seconds`` of wall time: at rest at the origin, PX4's own
    attitude, pose variances ``variance`` (the rest stated), velocity zero with 0.01 m²/s²."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        att = gs.last.get("ATTITUDE_QUATERNION")
        q = [att.q1, att.q2, att.q3, att.q4] if att is not None else [1.0, 0.0, 0.0, 0.0]
        pose = covariance21((variance, variance, variance, 1e-3, 1e-3, 1e-3))
        vel = covariance21((0.01, 0.01, 0.01, 1e-3, 1e-3, 1e-3))
        gs.send(M.MAVLink_odometry_message(0, frame, M.MAV_FRAME_BODY_FRD, 0.0, 0.0, 0.0, q, 0.0, 0.0, 0.0,
                                           0.0, 0.0, 0.0, pose, vel, 0, estimator_type, quality))
        time.sleep(1.0 / (30 * 5))


def test_ekf2_takes_odometry_by_estimator_type_frame_covariance_and_quality(px4):
    """What PX4 does with an ODOMETRY (measured, the values its receiver and EKF2 publish): VISION
    and VIO are external vision, MOCAP motion capture, GPS is refused; LOCAL_NED and LOCAL_FRD are
    taken as such; EKF2 fuses the message's position variance, floored at EKF2_EVP_NOISE² (0.1 m);
    below EKF2_EV_QMIN a sample is not fused."""
    with GroundStation(px4) as gs:
        gs.feed_gps()
        _send_odometry(gs, 2.0, variance=0.25)
        vo = listener(px4, "vehicle_visual_odometry")
        aid = listener(px4, "estimator_aid_src_ev_pos")
        assert int(_number(vo["pose_frame"])) == 1 and int(_number(vo["quality"])) == 100  # NED
        assert _number(aid["observation_variance"]) == pytest.approx(0.25, rel=1e-3)
        assert aid["fused"] == "True"
        _send_odometry(gs, 0.6, frame=M.MAV_FRAME_LOCAL_FRD, variance=1e-4,
                       estimator_type=M.MAV_ESTIMATOR_TYPE_VIO)
        vo, aid = listener(px4, "vehicle_visual_odometry"), listener(px4, "estimator_aid_src_ev_pos")
        assert int(_number(vo["pose_frame"])) == 2  # FRD
        assert _number(aid["observation_variance"]) == pytest.approx(0.01, rel=1e-3)  # EKF2_EVP_NOISE²
        before = _number(listener(px4, "vehicle_visual_odometry")["timestamp"].split()[0])
        _send_odometry(gs, 0.4, estimator_type=M.MAV_ESTIMATOR_TYPE_MOCAP)
        assert listener(px4, "vehicle_mocap_odometry")  # motion capture goes to its own topic
        _send_odometry(gs, 0.4, estimator_type=M.MAV_ESTIMATOR_TYPE_GPS)
        after = _number(listener(px4, "vehicle_visual_odometry")["timestamp"].split()[0])
        assert after == before  # neither MOCAP nor GPS reached external vision
        _set_int(gs, "EKF2_EV_QMIN", 50)
        _send_odometry(gs, 1.0, quality=20)
        assert listener(px4, "estimator_aid_src_ev_pos")["fused"] == "False"
        _send_odometry(gs, 1.0, quality=80)
        assert listener(px4, "estimator_aid_src_ev_pos")["fused"] == "True"
        _set_int(gs, "EKF2_EV_QMIN", 0)
    assert "estimator_type 4 unsupported" in px4.log_path.read_text(errors="replace")
