"""The companion on a u-blox receiver it owns (``--coupling tight --ubx URL``): the UBX stream read on a
thread from a real TCP socket, and the node putting the receiver's raw epochs on the autopilot's boot
clock, into the tightly coupled filter, and out as GPS_INPUT with its own accuracy."""

from __future__ import annotations

import math
import time
from collections import Counter

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.autopilot.node import AutopilotCompanion, CompanionConfig
from companion.autopilot.service import config_from_args
from companion.errors import UserError
from companion.gnss.geometry import ecef_to_geodetic, geodetic_to_ecef
from companion.gnss.systems import System
from companion.gnss.timescale import gps_to_unix_s
from companion.receiver.raw_receiver import RawReceiver
from tests.gnss_helpers import RX_ECEF, T0, observe, serve_bytes_once, store
from tests.test_autopilot_adapter import _FakeConn, _from
from tests.test_gnss_readers import _ubx_frames


def test_raw_receiver_reads_ubx_from_tcp_on_a_thread():
    items: list = []
    with serve_bytes_once(_ubx_frames(), 61, 0.001) as port:
        rx = RawReceiver(f"tcp:127.0.0.1:{port}")
        deadline = time.monotonic() + 10.0
        try:
            while time.monotonic() < deadline and not rx.counters().get("disconnects"):
                items += rx.drain()
                time.sleep(0.01)
            items += rx.drain()
        finally:
            rx.close()
    assert [type(i).__name__ for i in items] == ["GnssEpoch", "KeplerEphemeris", "ReceiverPvt", "GnssEpoch"]
    c = rx.counters()
    assert c["items"] == 4 and c["disconnects"] == 1 and c["junk_bytes"] == len(b"line noise between frames")


def test_bad_receiver_options_are_one_line_errors(tmp_path):
    import argparse

    from companion.autopilot.options import add_master_arguments

    p = argparse.ArgumentParser()
    add_master_arguments(p, master_required=True)
    p.add_argument("--method", default="second-order")
    base = ["--master", "udpin::14550", "--out", str(tmp_path)]
    with pytest.raises(UserError, match="--ubx"):
        config_from_args(p.parse_args(base + ["--coupling", "tight"]))
    with pytest.raises(UserError, match="--coupling tight"):
        config_from_args(p.parse_args(base + ["--ubx", "tcp:127.0.0.1:1"]))
    with pytest.raises(UserError, match="second-order"):
        tight = ["--coupling", "tight", "--ubx", "tcp:h:1", "--method", "vbakf"]
        config_from_args(p.parse_args(base + tight))
    with pytest.raises(UserError, match="cannot connect"):
        RawReceiver("tcp:127.0.0.1:1")


def test_node_fuses_the_receivers_raw_epochs_and_feeds_gps_input(tmp_path):
    st = store()
    conn = _FakeConn()
    conn.counters = Counter()
    config = CompanionConfig(master="udpin::14550", out_dir=tmp_path, coupling="tight", ubx="tcp:unused:1",
                             feed="gps-input")
    node = AutopilotCompanion(config, conn)  # type: ignore[arg-type]
    hb = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0, 3)
    node.handle(_from(hb, 3, 1), -2.0)
    node.handle(_from(hb, 3, 1), 0.0)  # two HEARTBEATs elect the autopilot
    node.raw_items([observe(st, T0, RX_ECEF)[0]])  # before the autopilot's clock: counted
    boot0_us = 1_000_000  # the autopilot's boot time at GPS time T0
    sys_time = mavlink.MAVLink_system_time_message(round(gps_to_unix_s(T0) * 1e6), boot0_us // 1000)
    node.handle(_from(sys_time, 3, 1), 0.0)
    lat, lon, h = (float(v) for v in ecef_to_geodetic(RX_ECEF))
    lat_e7, lon_e7 = round(math.degrees(lat) * 1e7), round(math.degrees(lon) * 1e7)
    def fix(t_us: int) -> mavlink.MAVLink_gps_raw_int_message:
        return mavlink.MAVLink_gps_raw_int_message(t_us, 3, lat_e7, lon_e7, round(h * 1e3), 100, 100, 0, 0,
                                                   12)

    node.raw_items([*st.kepler, *st.glonass])  # the receiver's decoded ephemerides (GLONASS's too)
    for k in range(300):  # 6 s at 50 Hz; an epoch every 0.2 s
        t_us = boot0_us + 20_000 * k
        att = mavlink.MAVLink_attitude_quaternion_message(t_us // 1000, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        imu = mavlink.MAVLink_highres_imu_message(t_us, 0, 0, -9.80665, *[0] * 10, 0b111111, 0)
        node.handle(_from(att, 3, 1), k * 0.02)
        if k % 10 == 0:  # the autopilot's fixes: the frame, once they agree (as in loose coupling)
            node.handle(_from(fix(t_us), 3, 1), k * 0.02)
        node.handle(_from(imu, 3, 1), k * 0.02)
        if k % 10 == 0:
            node.raw_items([observe(st, T0 + k * 0.02, RX_ECEF)[0]])
    c = node.counters  # until the autopilot's fixes agree on a frame, epochs wait for the navigator
    assert c["raw_before_system_time"] == 1 and c["raw_epochs"] + c["raw_before_first_fix"] == 30
    assert c["raw_epochs"] >= 25
    nav = node.nav_counters()
    assert nav["gnss_fused"] >= c["raw_epochs"] - 2 and nav["gnss_resets"] == 0
    assert nav["gnss_fix_ignored"] >= 1
    # every tracked satellite has its ephemeris, GLONASS's too: all are used
    info = node.nav.engine.entries[-1].info
    n_glonass = int(np.sum(observe(st, T0, RX_ECEF)[0].system == System.GLONASS))
    assert n_glonass > 0 and info.n_used == info.n_sats
    assert int(np.sum(info.key // 1000 == System.GLONASS)) == n_glonass
    feeds = [m for m in conn.sent if m.get_type() == "GPS_INPUT"]
    assert len(feeds) > 40
    last = feeds[-1]
    p = geodetic_to_ecef(math.radians(last.lat / 1e7), math.radians(last.lon / 1e7), last.alt)
    assert np.linalg.norm(p[:2] - RX_ECEF[:2]) < 3.0  # horizontal ECEF components near the truth
    assert 0.0 < last.horiz_accuracy < 5.0 and last.fix_type == 3
    s = node.summary(1.0)
    assert s["coupling"] == "tight" and s["samples"]["used"]["gnss"] >= 23


@pytest.mark.parametrize(("autopilot", "lag_option_us", "lag_us"), [
    (mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, None, 80_000),  # its receiver delay (GPS2_DELAY_MS = 80 ms)
    (mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 84_000, 84_000),  # --clock-lag-ms 84
    (mavlink.MAV_AUTOPILOT_PX4, None, 0)])  # PX4's SYSTEM_TIME is its host's clock
def test_raw_epochs_are_put_on_boot_time_before_the_autopilots_lagging_clock(
        tmp_path, autopilot, lag_option_us, lag_us):
    """ArduPilot sets its clock from a fix's GPS time when the fix arrives: its SYSTEM_TIME lags GPS time
    by that receiver's latency (84 ms beside the 80 ms canyon receiver). An epoch measured at GPS time
    T is at boot time (T as Unix time) − (SYSTEM_TIME's Unix − boot) − that lag."""
    from companion.autopilot.translate import TranslateConfig
    from companion.domain.geodesy import LocalNedFrame
    from companion.tight import RawGnss

    lat, lon, h = (float(v) for v in ecef_to_geodetic(RX_ECEF))
    config = CompanionConfig(master="udpin::14550", out_dir=tmp_path, coupling="tight", ubx="tcp:unused:1",
                             home=LocalNedFrame(math.degrees(lat), math.degrees(lon), h),
                             clock_lag_us=lag_option_us,
                             translate=TranslateConfig(gnss_delay_us=80_000))
    node = AutopilotCompanion(config, _FakeConn())  # type: ignore[arg-type]
    hb = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, autopilot, 0, 0, 0, 3)
    node.handle(_from(hb, 3, 1), -2.0)
    node.handle(_from(hb, 3, 1), 0.0)
    boot0_us = 1_000_000  # the autopilot's boot time at ITS Unix time gps_to_unix(T0)
    sys_time = mavlink.MAVLink_system_time_message(round(gps_to_unix_s(T0) * 1e6), boot0_us // 1000)
    node.handle(_from(sys_time, 3, 1), 0.0)
    node._start_navigator()
    pushed: list[int] = []
    node.nav.push = lambda sample: pushed.append(sample.t_us) if isinstance(sample, RawGnss) else None  # type: ignore[union-attr]
    epoch = observe(store(), T0 + 0.4, RX_ECEF)[0]
    node.raw_items([epoch])
    since_us = round((gps_to_unix_s(epoch.t_gps_s) - gps_to_unix_s(T0)) * 1e6)  # 0.4 s (its receiver's tag)
    assert abs(since_us - 400_000) < 100
    assert pushed == [boot0_us + since_us - lag_us] and node.clock_lag_us == lag_us
