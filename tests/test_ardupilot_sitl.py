"""The ArduCopter SITL launcher: a real firmware process, its ports, parameters from boot, clean stop."""

from __future__ import annotations

import math
import time

import pytest
from ardupilot_helpers import require_ardupilot
from pymavlink import mavutil

from companion.errors import UserError
from simvehicle.harness.ardupilot.sitl import (
    ArduPilotSitl,
    SitlConfig,
    instance_ports,
    port_listening,
    write_param_file,
)


def test_instance_ports_and_param_file(tmp_path):
    assert instance_ports(0) == (5760, 5762, 5763)
    assert instance_ports(3) == (5790, 5792, 5793)
    path = write_param_file(tmp_path / "x.parm", {"GPS1_TYPE": 14, "SIM_GPS1_GLTCH_X": 1e-4})
    assert path.read_text() == "GPS1_TYPE 14\nSIM_GPS1_GLTCH_X 0.0001\n"
    with pytest.raises(UserError, match="parameter name"):
        write_param_file(tmp_path / "y.parm", {"gps1_type": 14})
    with pytest.raises(UserError, match="finite"):
        write_param_file(tmp_path / "y.parm", {"GPS1_TYPE": math.nan})


def test_missing_binary_is_one_line_error(tmp_path):
    with pytest.raises(UserError, match="binary not found"):
        ArduPilotSitl(SitlConfig(work_dir=tmp_path, binary=tmp_path / "nope"))


def test_sitl_starts_on_a_free_instance_with_boot_params_and_stops(tmp_path):
    require_ardupilot()
    sitl = ArduPilotSitl(SitlConfig(work_dir=tmp_path / "ap", speedup=10, params={"GPS1_TYPE": 14}))
    with sitl:
        assert sitl.running()
        conn = mavutil.mavlink_connection(sitl.url, source_system=255, source_component=190)
        try:
            hb = conn.wait_heartbeat(timeout=20)
            assert hb is not None and hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
            conn.mav.param_request_read_send(conn.target_system, conn.target_component, b"GPS1_TYPE", -1)
            deadline = time.monotonic() + 10
            value = None
            while time.monotonic() < deadline and (value is None or value.param_id != "GPS1_TYPE"):
                # (ArduPilot also announces parameters it changes itself, e.g. BARO1_GND_PRESS)
                value = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
            assert value is not None and value.param_id == "GPS1_TYPE" and value.param_value == 14.0
        finally:
            conn.close()
    assert not sitl.running() and not port_listening(sitl.ports[0])
    assert (tmp_path / "ap" / "eeprom.bin").is_file() and (tmp_path / "ap" / "arducopter.log").is_file()
