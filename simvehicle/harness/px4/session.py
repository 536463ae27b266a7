"""The MAVLink loop against one PX4 SITL (SIH): streams in, HIL_GPS and OFFBOARD setpoints out.

One UDP connection to PX4's GCS link (``udpout:127.0.0.1:18570 + i``; PX4 answers to the address it
hears from), recorded both ways to the tlog (``companion.autopilot.connection.MavConnection``),
carries the GNSS source and the flight driver, as the vehicle's own system id (PX4 takes HIL_GPS
only from its own system id) and component 190. PX4's boot time (HIGHRES_IMU ``time_usec``) is
the clock. The companion, in closed loop, has PX4's onboard link to itself (14540 + i).

- Truth: HIL_STATE_QUATERNION (SIH's ground truth; PX4 fills no ``time_usec``) stamped with the
  latest HIGHRES_IMU's time. Against the ULog's ground truth this stamp is 10-15 ms early
  (measured), i.e. a few centimetres at cruise speed, the same for every row.
- PX4's estimate: LOCAL_POSITION_NED placed in the mission frame with ``origin_ned_m`` (horizontal:
  GPS_GLOBAL_ORIGIN, EKF2's origin; vertical: EKF2's height on the ground before arming is the
  mission's ground). With external vision and an origin set over MAVLink, EKF2 (this build)
  moves its local height by the origin's altitude (its global altitude is then wrong by that
  much; measured: ``z`` = +489 m on the ground at Zurich); heights above the take-off point are
  unaffected, which is what the setpoints and this placement use.
- Streams: PX4's GCS link sends a dozen streams at 50 Hz by default; those not needed are turned
  off (interval -1) so that the session keeps up at the speed factor.
- Command delay (``foreign.session``): TIMESYNC probes answered by PX4 (``tc1`` = its time at
  arrival); PX4's own TIMESYNC requests (10 Hz) are not answered on this link (nothing we send
  it here carries a stamp PX4 would map).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

import numpy as np  # noqa: E402
from pymavlink.dialects.v20 import common as MSG  # noqa: E402, N812 - as mavutil.mavlink

from companion.autopilot.connection import MavConnection, parse_connection  # noqa: E402
from companion.domain.geodesy import LocalNedFrame  # noqa: E402
from companion.errors import UserError  # noqa: E402
from simvehicle.harness.foreign.driver import RouteDriver  # noqa: E402
from simvehicle.harness.foreign.gnss_source import GnssSource, SentFix  # noqa: E402
from simvehicle.harness.foreign.session import ForeignSession  # noqa: E402
from simvehicle.harness.px4.config import Px4FlightConfig  # noqa: E402

FLIGHT_TOOL_COMPONENT_ID = 190  # MAV_COMP_ID_MISSIONPLANNER
HEARTBEAT_PERIOD_S = 1.0  # ours, wall clock (PX4 learns our address from it first)
ESTIMATOR_POS_HORIZ_ABS = 16  # ESTIMATOR_STATUS flags
UINT16_UNKNOWN = 65535
# PX4's GCS-link streams (px4-rc.mavlink) that the session does not read: turned off
UNUSED_STREAMS = ("ATTITUDE", "ATTITUDE_TARGET", "POSITION_TARGET_LOCAL_NED", "SERVO_OUTPUT_RAW",
                  "RC_CHANNELS", "OPTICAL_FLOW_RAD", "VFR_HUD", "ALTITUDE", "DISTANCE_SENSOR",
                  "GLOBAL_POSITION_INT", "GPS_RAW_INT", "SCALED_PRESSURE", "SYS_STATUS",
                  "OPEN_DRONE_ID_LOCATION", "OPEN_DRONE_ID_SYSTEM", "BATTERY_STATUS", "VIBRATION", "PING",
                  "EXTENDED_SYS_STATE")


def hil_gps_fields(sf: SentFix) -> dict[str, int]:
    """HIL_GPS fields (MAVLink common) for a fix, as PX4's receiver reads them.

    PX4 (``mavlink_receiver``) reads ``eph``/``epv`` as accuracies in cm (MAVLink calls them
    DOP × 100), so they carry the model's reported accuracy (the white-noise std; EKF2 floors it
    at ``EKF2_GPS_P_NOISE``). It stamps the fix at arrival and keeps ``time_usec`` only as UTC
    time: here the validity time (boot µs), for the record. Velocity in cm/s when the fix has one
    (PX4 marks every HIL_GPS velocity valid: without one, zeros are sent and EKF2 must not fuse
    velocity, ``EKF2_GPS_CTRL`` without bit 2)."""
    fix, v = sf.fix, sf.v_ned_m_s
    acc = fix.h_acc_m if np.isfinite(fix.h_acc_m) else 1.0
    vacc = fix.v_acc_m if np.isfinite(fix.v_acc_m) else 1.5
    vel = np.zeros(3) if v is None else np.asarray(v, dtype=float)
    ground_cm_s = round(100 * float(np.hypot(vel[0], vel[1])))
    cog = UINT16_UNKNOWN if v is None or ground_cm_s == 0 else round(
        100 * float(np.degrees(np.arctan2(vel[1], vel[0]))) % 36000)
    return {
        "time_usec": int(fix.t_validity_us),
        "fix_type": int(fix.fix_type),
        "lat": round(fix.lat_deg * 1e7),
        "lon": round(fix.lon_deg * 1e7),
        "alt": round(fix.alt_m * 1e3),
        "eph": min(max(round(100 * acc), 1), UINT16_UNKNOWN - 1),
        "epv": min(max(round(100 * vacc), 1), UINT16_UNKNOWN - 1),
        "vel": min(ground_cm_s, UINT16_UNKNOWN - 1),
        "vn": round(100 * vel[0]),
        "ve": round(100 * vel[1]),
        "vd": round(100 * vel[2]),
        "cog": int(cog),
        "satellites_visible": int(fix.satellites_visible),
    }


class Px4Session(ForeignSession):
    feed_stamps = {"ODOMETRY": "time_usec"}  # the companion's ODOMETRY, forwarded from the onboard link

    def __init__(self, url: str, system_id: int, cfg: Px4FlightConfig, frame: LocalNedFrame,
                 source: GnssSource, driver: RouteDriver, tlog_path: Path) -> None:
        super().__init__(frame, source, driver, tlog_path, cfg.setup_timeout_s, cfg.wall_timeout_s)
        self.url, self.system_id, self.cfg = url, system_id, cfg
        self.origin_lla: tuple[float, float, float] | None = None  # EKF2's origin (GPS_GLOBAL_ORIGIN)
        self.ground_z_m: float | None = None  # EKF2's local z on the ground before arming
        self._next_heartbeat_s = 0.0

    # ---------------------------------------------------------------- wiring
    def connect(self, alive: Any) -> None:
        """Open the GCS link (recorded both ways), wait for PX4's HEARTBEAT, set the streams."""
        self.conn = MavConnection(parse_connection(self.url), self.system_id, FLIGHT_TOOL_COMPONENT_ID,
                                  self.tlog)
        deadline = time.monotonic() + self.cfg.connect_timeout_s
        px4 = (self.system_id, 1)  # PX4's autopilot component
        while self.target is None:
            if time.monotonic() > deadline or not alive():
                raise UserError(f"PX4 SITL on {self.url}: no HEARTBEAT within "
                                f"{self.cfg.connect_timeout_s:g} s")
            self._before_recv()
            for msg in self.conn.recv(0.3):
                if msg.get_type() == "HEARTBEAT" and (msg.get_srcSystem(), msg.get_srcComponent()) == px4:
                    self.target = px4
        fast, est = self.cfg.stream_rate_hz, self.cfg.estimate_rate_hz
        wanted = (("HIGHRES_IMU", fast), ("ATTITUDE_QUATERNION", fast), ("HIL_STATE_QUATERNION", fast),
                  ("LOCAL_POSITION_NED", est), ("GPS_GLOBAL_ORIGIN", 1.0), ("ESTIMATOR_STATUS", 2.0),
                  ("HEARTBEAT", 1.0))
        for name, hz in wanted:
            self._command(MSG.MAV_CMD_SET_MESSAGE_INTERVAL, getattr(MSG, f"MAVLINK_MSG_ID_{name}"), 1e6 / hz,
                          0, 0, 0, 0, 0)
        for name in UNUSED_STREAMS:
            self._command(MSG.MAV_CMD_SET_MESSAGE_INTERVAL, getattr(MSG, f"MAVLINK_MSG_ID_{name}"), -1,
                          0, 0, 0, 0, 0)

    def _before_recv(self) -> None:
        now = time.monotonic()
        if now >= self._next_heartbeat_s and self.conn is not None:
            self._next_heartbeat_s = now + HEARTBEAT_PERIOD_S
            self.conn.send(MSG.MAVLink_heartbeat_message(MSG.MAV_TYPE_GCS, MSG.MAV_AUTOPILOT_INVALID,
                                                         0, 0, 0, 3))

    # ---------------------------------------------------------------- PX4's messages
    def _handle_vehicle(self, kind: str, msg: Any) -> None:
        now = self.now
        if kind == "HIL_STATE_QUATERNION":  # SIH's truth
            p = self.frame.to_ned_m(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3)
            self._record_truth(p, np.array([msg.vx, msg.vy, msg.vz], dtype=float) * 0.01)
        elif kind == "LOCAL_POSITION_NED":
            self._local(msg)
        elif kind == "GPS_GLOBAL_ORIGIN":
            self.origin_lla = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
            self._place_local_frame()
        elif kind == "HEARTBEAT":
            now.mode = int(msg.custom_mode)
            now.armed = bool(msg.base_mode & MSG.MAV_MODE_FLAG_SAFETY_ARMED)
        elif kind == "ESTIMATOR_STATUS":
            now.ekf_position_ok = bool(msg.flags & ESTIMATOR_POS_HORIZ_ABS)

    def _local(self, msg: Any) -> None:
        p_local = np.array([msg.x, msg.y, msg.z], dtype=float)
        if not np.isfinite(p_local).all():
            self.rec.reject("local_position_non_finite")
            return
        if not self.now.armed and self.driver.route_t0_us is None:
            self.ground_z_m = float(p_local[2])  # on the ground: the take-off point's height in EKF2's frame
            self._place_local_frame()
        o = self.now.origin_ned_m
        if o is None:
            return
        p = p_local + o
        self.rec.ekf_t_us.append(int(msg.time_boot_ms) * 1000)
        self.rec.ekf_p_ned_m.append(p)
        self.now.ekf_ned_m = p
        self.now.ekf_height_m = -float(p[2])

    def _place_local_frame(self) -> None:
        """``origin_ned_m``: PX4's local frame origin in the mission frame (see the module doc)."""
        if self.origin_lla is None or self.ground_z_m is None:
            return
        o = self.frame.to_ned_m(*self.origin_lla)
        self.now.origin_ned_m = np.array([o[0], o[1], -self.ground_z_m])

    def _send_fix(self, sf: SentFix) -> None:
        assert self.conn is not None
        self.conn.send(MSG.MAVLink_hil_gps_message(**hil_gps_fields(sf)))
