"""The PX4 SITL launcher (simvehicle.harness.px4.sitl) and its test fixture (px4_helpers): free
instances side by side, parameters in force from boot, a reboot keeping them, nothing left behind."""

from __future__ import annotations

import os
import socket
import struct
import time

import pytest
from px4_helpers import running_px4
from pymavlink.dialects.v20 import common as mavlink

from companion.errors import UserError
from companion.mavlink.frames import pack_frame, parse_datagram
from simvehicle.harness.px4.sitl import SOCKET_PATH, Px4Config, Px4Sitl


def _param(px4: Px4Sitl, name: str, timeout_s: float = 10.0) -> float:
    """``name`` read from the running PX4 over its onboard link (PARAM_REQUEST_READ)."""
    ask = pack_frame(mavlink.MAVLink_param_request_read_message(px4.system_id, 1, name.encode(), -1), 0,
                     px4.system_id, 197)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", px4.offboard_port))
        s.settimeout(0.2)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            s.sendto(ask, ("127.0.0.1", px4.offboard_port + 40))  # its onboard link listens on 14580 + i
            try:
                views, _ = parse_datagram(s.recv(65_535))
            except TimeoutError:
                continue
            for v in views:
                if v.get_type() == "PARAM_VALUE" and v.param_id == name:
                    if v.param_type == mavlink.MAV_PARAM_TYPE_INT32:  # PX4 sends integers bytewise
                        return float(struct.unpack("<i", struct.pack("<f", v.param_value))[0])
                    return float(v.param_value)
    raise AssertionError(f"{name} not read")


def test_two_px4s_side_by_side_with_parameters_from_boot_and_nothing_left(tmp_path):
    with running_px4(tmp_path / "a", params={"EKF2_GPS_DELAY": 150}) as a, running_px4(tmp_path / "b") as b:
        assert a.instance != b.instance and (a.system_id, b.system_id) == (a.instance + 1, b.instance + 1)
        assert a.url == f"udpin:127.0.0.1:{14540 + a.instance}"
        assert _param(a, "EKF2_GPS_DELAY") == 150.0 and _param(a, "SDLOG_MODE") == -1.0  # no ULog by default
        assert _param(b, "EKF2_GPS_DELAY") != 150.0
        a.restart()  # a reboot: the same instance, its stored parameters kept
        assert a.running() and _param(a, "EKF2_GPS_DELAY") == 150.0
        instances = (a.instance, b.instance)
    for i in instances:  # running_px4 checked its process is gone; the sockets too:
        assert not os.path.exists(SOCKET_PATH.format(i))
    assert not list((tmp_path / "a" / "rootfs" / "log").glob("**/*.ulg"))


def test_bad_configurations_are_one_line_errors(tmp_path):
    with pytest.raises(UserError, match="PX4 SITL not found"):
        Px4Sitl(Px4Config(tmp_path, px4_dir=tmp_path / "nowhere"))
    with pytest.raises(UserError, match="speed factor must be positive"):
        Px4Sitl(Px4Config(tmp_path, speed_factor=float("nan")))
    from px4_helpers import require_px4

    require_px4()
    sitl = Px4Sitl(Px4Config(tmp_path, params={"ekf2 gps": 1}))
    with pytest.raises(UserError, match="bad PX4 parameter name"):
        sitl.start()
    assert sitl.process is None  # refused before anything started
