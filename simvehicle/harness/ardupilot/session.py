"""The MAVLink loop against one ArduCopter SITL: streams in, GPS_INPUT and flight commands out.

One TCP connection to SERIAL0 (``companion.autopilot.connection.MavConnection``, which records
every frame both ways to the tlog) carries the GNSS source and the flight driver; ArduPilot's own
boot time (the IMU stamps) is the clock. The raw fixes go to receiver ``raw_gps_id``: GPS1 in
open loop (EKF3 flies on them), GPS2 in closed loop (read by the companion process, which has its
own connection and feeds ArduPilot itself). Each SIM_STATE (truth, no time field) is stamped with
the HIGHRES_IMU sent in the same scheduler tick (requested at the same rate, it immediately precedes it). What
arrives is recorded for the analysis (``Recording``).

The setpoints are in EKF3's local frame, placed in the mission frame by ``origin_ned_m``: horizontally
EKF3's origin (GPS_GLOBAL_ORIGIN), vertically EKF3's height on the ground before arming, which is the
mission's ground. EKF3's height is the barometer's (``EK3_SRC1_POSZ`` 1); the origin's ALTITUDE is
the GNSS altitude of the fix that set it, which in a canyon is tens of metres off (21 m measured:
the vehicle, told the origin's altitude was the ground, flew its route into the ground). Its
global altitude (GLOBAL_POSITION_INT ``alt``, the autopilot row) keeps that error; heights above
the take-off point do not, and they are what the setpoints use, as for PX4.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

import numpy as np  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as MSG  # noqa: E402, N812 - as mavutil.mavlink

from companion.autopilot.connection import MavConnection, parse_connection  # noqa: E402
from companion.domain.geodesy import LocalNedFrame  # noqa: E402
from companion.errors import UserError  # noqa: E402
from simvehicle.harness.ardupilot.config import GPS1_ID, ArduPilotConfig  # noqa: E402
from simvehicle.harness.ardupilot.driver import FlightDriver  # noqa: E402
from simvehicle.harness.ardupilot.gnss_source import gps_input_fields  # noqa: E402
from simvehicle.harness.foreign.gnss_source import GnssSource, SentFix  # noqa: E402
from simvehicle.harness.foreign.session import ForeignSession  # noqa: E402

GCS_SYSTEM_ID, GCS_COMPONENT_ID = 255, 190
EKF_POS_HORIZ_ABS, EKF_CONST_POS_MODE = 16, 128  # EKF_STATUS_REPORT flags (ardupilotmega EKF_STATUS_FLAGS)


class ArduPilotSession(ForeignSession):
    # the companion's feeds, stamped with its estimate's time (ArduPilot boot µs)
    feed_stamps = {"GPS_INPUT": "time_usec", "VISION_POSITION_ESTIMATE": "usec"}

    def __init__(self, port: int, cfg: ArduPilotConfig, frame: LocalNedFrame, source: GnssSource,
                 driver: FlightDriver, tlog_path: Path, raw_gps_id: int = GPS1_ID) -> None:
        super().__init__(frame, source, driver, tlog_path, cfg.setup_timeout_s, cfg.wall_timeout_s)
        self.cfg = cfg
        self.raw_gps_id = raw_gps_id  # the receiver our raw fixes go to (GPS2 in closed loop)
        self.port = port
        self._velocity_sigma_m_s = source.velocity_sigma_m_s or 0.0
        self.origin_lla: tuple[float, float, float] | None = None  # EKF3's origin (GPS_GLOBAL_ORIGIN)
        self.ground_alt_m: float | None = None  # EKF3's altitude on the ground before arming

    # ---------------------------------------------------------------- wiring
    def connect(self, alive: Any) -> None:
        """Connect to SERIAL0 (``companion.autopilot.connection``, recorded both ways to the tlog),
        wait for the autopilot's HEARTBEAT and ask for the streams."""
        deadline = time.monotonic() + self.cfg.connect_timeout_s
        url = f"tcp:127.0.0.1:{self.port}"
        while self.conn is None:
            if not alive():
                raise UserError("ArduPilot SITL exited before accepting a connection (see arducopter.log)")
            try:
                self.conn = MavConnection(parse_connection(url), GCS_SYSTEM_ID, GCS_COMPONENT_ID, self.tlog)
            except UserError:
                if time.monotonic() > deadline:
                    raise UserError(f"ArduPilot SITL: nothing accepts on {url}") from None
                time.sleep(0.2)
        while self.target is None:
            if time.monotonic() > deadline or not alive():
                raise UserError(f"ArduPilot SITL on {url}: no HEARTBEAT")
            for msg in self.conn.recv(0.5):
                if msg.get_type() == "HEARTBEAT" and msg.autopilot != MSG.MAV_AUTOPILOT_INVALID:
                    self.target = (msg.get_srcSystem(), msg.get_srcComponent())
        fast, est = self.cfg.stream_rate_hz, self.cfg.estimate_rate_hz
        streams = (("HIGHRES_IMU", fast), ("ATTITUDE_QUATERNION", fast), ("SIM_STATE", fast),
                   ("GLOBAL_POSITION_INT", est), ("GPS_GLOBAL_ORIGIN", 1.0), ("EKF_STATUS_REPORT", 2.0))
        for name, hz in streams:
            msg_id = getattr(MSG, f"MAVLINK_MSG_ID_{name}")
            self._command(MSG.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz, 0, 0, 0, 0, 0)

    # ---------------------------------------------------------------- ArduPilot's messages
    def _handle_vehicle(self, kind: str, msg: Any) -> None:
        now = self.now
        if kind == "SIM_STATE":  # truth, no time field: the latest HIGHRES_IMU's (same scheduler tick)
            p = self.frame.to_ned_m(msg.lat_int * 1e-7, msg.lon_int * 1e-7, float(msg.alt))
            self._record_truth(p, np.array([msg.vn, msg.ve, msg.vd], dtype=float))
        elif kind == "GLOBAL_POSITION_INT":
            p = self.frame.to_ned_m(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3)
            self.rec.ekf_t_us.append(msg.time_boot_ms * 1000)
            self.rec.ekf_p_ned_m.append(p)
            now.ekf_ned_m = p
            now.ekf_height_m = msg.relative_alt * 1e-3
            if not now.armed and self.driver.route_t0_us is None and (msg.lat != 0 or msg.lon != 0):
                self.ground_alt_m = msg.alt * 1e-3  # on the ground: the take-off point in EKF3's heights
                self._place_local_frame()
        elif kind == "GPS_GLOBAL_ORIGIN":
            self.origin_lla = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
            self._place_local_frame()
        elif kind == "HEARTBEAT":
            now.mode = msg.custom_mode
            now.armed = bool(msg.base_mode & MSG.MAV_MODE_FLAG_SAFETY_ARMED)
            now.takeoff_accepted = now.takeoff_accepted and now.armed
        elif kind == "EKF_STATUS_REPORT":
            flags = msg.flags
            now.ekf_position_ok = bool(flags & EKF_POS_HORIZ_ABS) and not flags & EKF_CONST_POS_MODE
        elif kind == "COMMAND_ACK" and msg.command == MSG.MAV_CMD_NAV_TAKEOFF:
            now.takeoff_accepted = now.takeoff_accepted or msg.result == MSG.MAV_RESULT_ACCEPTED

    def _place_local_frame(self) -> None:
        """``origin_ned_m``: EKF3's local frame origin in the mission frame (see the module doc). EKF3's
        local z on the ground is (origin altitude − its altitude there); the mission's ground is D = 0."""
        if self.origin_lla is None or self.ground_alt_m is None:
            return
        o = self.frame.to_ned_m(*self.origin_lla)
        self.now.origin_ned_m = np.array([o[0], o[1], self.ground_alt_m - self.origin_lla[2]])

    def _send_fix(self, sf: SentFix) -> None:
        assert self.conn is not None
        self.conn.send(MSG.MAVLink_gps_input_message(**gps_input_fields(sf, self.raw_gps_id,
                                                                        self._velocity_sigma_m_s)))
