"""The MAVLink loop against one ArduCopter SITL: streams in, GPS_INPUT and flight commands out.

One TCP connection to SERIAL0 (``companion.autopilot.connection.MavConnection``, which records
every frame both ways to the tlog) carries the GNSS source and the flight driver; ArduPilot's own
boot time (the IMU stamps) is the clock. The raw fixes go to receiver ``raw_gps_id``: GPS1 in
open loop (EKF3 flies on them), GPS2 in closed loop (read by the companion process, which has its
own connection and feeds ArduPilot itself). Each SIM_STATE (truth, no time field) is stamped with
the HIGHRES_IMU sent in the same scheduler tick (requested at the same rate, it immediately precedes it). What
arrives is recorded for the analysis (``Recording``).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

import numpy as np  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as MSG  # noqa: E402, N812 - as mavutil.mavlink

from companion.autopilot.connection import MavConnection, parse_connection  # noqa: E402
from companion.domain.geodesy import LocalNedFrame  # noqa: E402
from companion.errors import UserError  # noqa: E402
from companion.mavlink.codec import CodecError, decode_attitude, decode_imu  # noqa: E402
from companion.mavlink.tlog import TlogWriter  # noqa: E402
from simvehicle.harness.ardupilot.config import GPS1_ID, ArduPilotConfig  # noqa: E402
from simvehicle.harness.ardupilot.driver import Command, DriverInputs, FlightDriver  # noqa: E402
from simvehicle.harness.ardupilot.gnss_source import UrbanGnssSource, gps_input_fields  # noqa: E402

SETPOINT_TYPE_MASK = MSG.POSITION_TARGET_TYPEMASK_YAW_IGNORE | MSG.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
GCS_SYSTEM_ID, GCS_COMPONENT_ID = 255, 190
TIMESYNC_PERIOD_US = 500_000  # ArduPilot time between command-delay probes
FEED_STAMPS = {"GPS_INPUT": "time_usec", "VISION_POSITION_ESTIMATE": "usec"}  # the companion's, boot µs
EKF_POS_HORIZ_ABS, EKF_CONST_POS_MODE = 16, 128  # EKF_STATUS_REPORT flags (ardupilotmega EKF_STATUS_FLAGS)


@dataclass
class Recording:
    """What the analysis needs, in ArduPilot boot time (µs)."""

    imu_t_us: list[int] = field(default_factory=list)
    imu_acc_frd_m_s2: list[np.ndarray] = field(default_factory=list)
    imu_q_ned_frd: list[np.ndarray] = field(default_factory=list)
    truth_t_us: list[int] = field(default_factory=list)
    truth_p_ned_m: list[np.ndarray] = field(default_factory=list)
    truth_v_ned_m_s: list[np.ndarray] = field(default_factory=list)
    truth_bias_ned_m: list[np.ndarray] = field(default_factory=list)
    truth_latency_s: list[float] = field(default_factory=list)
    truth_clearance_m: list[float] = field(default_factory=list)
    ekf_t_us: list[int] = field(default_factory=list)
    ekf_p_ned_m: list[np.ndarray] = field(default_factory=list)
    statustext: list[tuple[int, str]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)


class ArduPilotSession:
    def __init__(self, port: int, cfg: ArduPilotConfig, frame: LocalNedFrame, source: UrbanGnssSource,
                 driver: FlightDriver, tlog_path: Path, raw_gps_id: int = GPS1_ID) -> None:
        self.cfg, self.frame, self.source, self.driver = cfg, frame, source, driver
        self.raw_gps_id = raw_gps_id  # the receiver our raw fixes go to (GPS2 in closed loop)
        self.rec = Recording()
        self.port = port
        self.tlog = TlogWriter(tlog_path)
        self.conn: MavConnection | None = None
        self.target: tuple[int, int] | None = None  # the autopilot's (system, component)
        self.now = DriverInputs(t_us=0)
        self._q: np.ndarray | None = None
        self.gps_sent = 0
        self.setpoints_sent = 0
        self.acks: list[tuple[int, int, int]] = []  # (t_us, command, MAV_RESULT) of flight commands
        # How late what we send reaches ArduPilot, in ITS time: a TIMESYNC request carries the
        # ArduPilot time we had processed up to (ts1); the reply says when it arrived (tc1).
        self.command_delay_us: list[int] = []
        # Closed loop: how old the companion process's estimate is when ArduPilot forwards it to us
        # (our ArduPilot time then minus the estimate's stamp): its feed's lateness, in ArduPilot time.
        self.feed_delay_us: list[int] = []
        self._next_timesync_us = 0

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

    def _command(self, command: int, *params: float) -> None:
        assert self.conn is not None and self.target is not None
        self.conn.send(MSG.MAVLink_command_long_message(*self.target, command, 0, *params))

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.tlog.close()

    # ---------------------------------------------------------------- loop
    def run(self, alive: Any) -> str:
        """Pump messages until the driver is done; returns how it ended."""
        assert self.conn is not None
        wall_end = time.monotonic() + self.cfg.wall_timeout_s
        setup_end_us = round(self.cfg.setup_timeout_s * 1e6)
        while self.driver.phase != "done":
            batch = self.conn.recv(0.5)
            if not batch and not alive():
                return "sitl_exited"
            for msg in batch:
                self._handle(msg)
                if self.driver.phase == "done":
                    break
            if self.driver.phase in ("guided", "arm", "takeoff") and self.now.t_us > setup_end_us:
                return f"setup_timeout:{self.driver.phase}"
            if time.monotonic() > wall_end:
                return "wall_timeout"
        return self.driver.outcome

    def _count(self, name: str) -> None:
        self.rec.counts[name] = self.rec.counts.get(name, 0) + 1

    def _handle(self, msg: Any) -> None:
        kind = msg.get_type()
        self._count(kind)
        if kind in FEED_STAMPS and self.target is not None and msg.get_srcComponent() != self.target[1] \
                and self.now.t_us > 0:
            self.feed_delay_us.append(self.now.t_us - int(getattr(msg, FEED_STAMPS[kind])))
        if self.target is None or (msg.get_srcSystem(), msg.get_srcComponent()) != self.target:
            return  # not the autopilot (ArduPilot forwards the companion's broadcasts to every link)
        rec, now = self.rec, self.now
        try:
            if kind == "HIGHRES_IMU":
                imu = decode_imu(msg)
                now.t_us = imu.t_us
                if self._q is not None:
                    rec.imu_t_us.append(imu.t_us)
                    rec.imu_acc_frd_m_s2.append(imu.acc_frd_m_s2)
                    rec.imu_q_ned_frd.append(self._q)
                self._tick()
            elif kind == "ATTITUDE_QUATERNION":
                self._q = decode_attitude(msg).q_ned_frd
            elif kind == "SIM_STATE":
                self._truth(msg)
            elif kind == "GLOBAL_POSITION_INT":
                p = self.frame.to_ned_m(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3)
                rec.ekf_t_us.append(msg.time_boot_ms * 1000)
                rec.ekf_p_ned_m.append(p)
                now.ekf_ned_m = p
                now.ekf_height_m = msg.relative_alt * 1e-3
            elif kind == "GPS_GLOBAL_ORIGIN":
                now.origin_ned_m = self.frame.to_ned_m(msg.latitude * 1e-7, msg.longitude * 1e-7,
                                                       msg.altitude * 1e-3)
            elif kind == "HEARTBEAT":
                now.mode = msg.custom_mode
                now.armed = bool(msg.base_mode & MSG.MAV_MODE_FLAG_SAFETY_ARMED)
                now.takeoff_accepted = now.takeoff_accepted and now.armed
            elif kind == "TIMESYNC" and msg.tc1 != 0 and msg.ts1 > 0:
                self.command_delay_us.append(msg.tc1 // 1000 - msg.ts1 // 1000)
            elif kind == "EKF_STATUS_REPORT":
                flags = msg.flags
                now.ekf_position_ok = bool(flags & EKF_POS_HORIZ_ABS) and not flags & EKF_CONST_POS_MODE
            elif kind == "COMMAND_ACK" and msg.command != MSG.MAV_CMD_SET_MESSAGE_INTERVAL:
                self.acks.append((now.t_us, int(msg.command), int(msg.result)))
                if msg.command == MSG.MAV_CMD_NAV_TAKEOFF and msg.result == MSG.MAV_RESULT_ACCEPTED:
                    now.takeoff_accepted = True
            elif kind == "STATUSTEXT":
                rec.statustext.append((now.t_us, str(msg.text)))
        except CodecError as exc:
            rec.rejected[exc.reason] = rec.rejected.get(exc.reason, 0) + 1

    def _truth(self, msg: Any) -> None:
        if self.now.t_us == 0:
            return  # no IMU time yet to stamp it with
        p = self.frame.to_ned_m(msg.lat_int * 1e-7, msg.lon_int * 1e-7, float(msg.alt))
        v = np.array([msg.vn, msg.ve, msg.vd], dtype=float)
        g = self.source.on_truth(self.now.t_us, p, v)
        rec = self.rec
        rec.truth_t_us.append(self.now.t_us)
        rec.truth_p_ned_m.append(p)
        rec.truth_v_ned_m_s.append(v)
        rec.truth_bias_ned_m.append(g.bias_ned_m)
        rec.truth_latency_s.append(g.latency_s)
        rec.truth_clearance_m.append(g.clearance_m)
        self.now.truth_ned_m, self.now.truth_v_ned_m_s = p, v

    def _tick(self) -> None:
        t = self.now.t_us
        send = self.conn.send  # type: ignore[union-attr]
        if t >= self._next_timesync_us:
            self._next_timesync_us = t + TIMESYNC_PERIOD_US
            send(MSG.MAVLink_timesync_message(0, t * 1000))
        sigma = self.source.velocity_sigma_m_s or 0.0
        for sf in self.source.due(t):
            send(MSG.MAVLink_gps_input_message(**gps_input_fields(sf, self.raw_gps_id, sigma)))
            self.gps_sent += 1
        for c in self.driver.step(self.now):
            self._send(c)

    def _send(self, c: Command) -> None:
        if c.kind == "command_long":
            self._command(*c.args)
        elif c.kind == "setpoint":
            assert self.conn is not None and self.target is not None
            self.conn.send(MSG.MAVLink_set_position_target_local_ned_message(
                c.args[0], *self.target, MSG.MAV_FRAME_LOCAL_NED, SETPOINT_TYPE_MASK, *c.args[1:], 0.0, 0.0))
            self.setpoints_sent += 1
