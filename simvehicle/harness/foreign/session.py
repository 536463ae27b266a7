"""The MAVLink loop every foreign-autopilot flight shares: the autopilot's IMU stream as the clock,
its truth driving our GNSS source, the driver's commands out, how late they arrive.

A vehicle's session (``ardupilot.session.ArduPilotSession``, ``px4.session.Px4Session``) opens its
connection (``companion.autopilot.connection.MavConnection``, recorded both ways to the tlog) in
``connect`` and handles its own messages in ``_handle_vehicle``; this base handles the rest:

- HIGHRES_IMU (with the latest ATTITUDE_QUATERNION) is recorded for the companion's analysis and
  is the clock (``now.t_us``, the autopilot's boot time); each one ``_tick``s: a TIMESYNC probe
  every ``TIMESYNC_PERIOD_US``, the fixes the source releases (``_send_fix``), the driver's
  commands;
- truth (``_record_truth``, from the vehicle's truth message) drives the GNSS source;
- command delay: a TIMESYNC request carries the autopilot time we had processed (``ts1``); the
  autopilot's answer says when it arrived (``tc1``), i.e. how late our fixes and setpoints are in
  ITS time (neither SITL waits for us);
- feed delay (closed loop): the companion's feed, forwarded by the autopilot to our link, is
  stamped with its estimate's time: our autopilot time at arrival minus that stamp.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

import numpy as np  # noqa: E402
from pymavlink.dialects.v20 import common as MSG  # noqa: E402, N812 - as mavutil.mavlink

from companion.autopilot.connection import MavConnection  # noqa: E402
from companion.domain.geodesy import LocalNedFrame  # noqa: E402
from companion.mavlink.codec import CodecError, decode_attitude, decode_imu  # noqa: E402
from companion.mavlink.tlog import TlogWriter  # noqa: E402
from simvehicle.harness.foreign.companion_process import COMPANION_COMPONENT_ID  # noqa: E402
from simvehicle.harness.foreign.driver import Command, DriverInputs, RouteDriver  # noqa: E402
from simvehicle.harness.foreign.gnss_source import GnssSource, SentFix  # noqa: E402
from simvehicle.harness.foreign.recording import Recording  # noqa: E402

SETPOINT_TYPE_MASK = MSG.POSITION_TARGET_TYPEMASK_YAW_IGNORE | MSG.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
TIMESYNC_PERIOD_US = 500_000  # autopilot time between command-delay probes


class ForeignSession:
    """The shared part of a session; ``target`` is the autopilot's (system, component) once known."""

    feed_stamps: dict[str, str] = {}  # the companion's feed messages and their stamp field (boot µs)

    def __init__(self, frame: LocalNedFrame, source: GnssSource, driver: RouteDriver,
                 tlog_path: Path, setup_timeout_s: float, wall_timeout_s: float) -> None:
        self.frame, self.source, self.driver = frame, source, driver
        self.setup_timeout_s, self.wall_timeout_s = setup_timeout_s, wall_timeout_s
        self.rec = Recording()
        self.tlog = TlogWriter(tlog_path)
        self.conn: MavConnection | None = None
        self.target: tuple[int, int] | None = None
        self.now = DriverInputs(t_us=0)
        self._q: np.ndarray | None = None
        self.gps_sent = 0
        self.setpoints_sent = 0
        self.acks: list[tuple[int, int, int]] = []  # (t_us, command, MAV_RESULT) of flight commands
        self.command_delay_us: list[int] = []
        self.feed_delay_us: list[int] = []
        self._next_timesync_us = 0

    # ---------------------------------------------------------------- vehicle hooks
    def connect(self, alive: Any) -> None:  # pragma: no cover - each vehicle's
        """Open the connection, find the autopilot (``target``), ask for the streams."""
        raise NotImplementedError

    def _send_fix(self, sf: SentFix) -> None:  # pragma: no cover - each vehicle's
        raise NotImplementedError

    def _handle_vehicle(self, kind: str, msg: Any) -> None:
        """The vehicle's own messages (truth, estimate, state); CodecError is counted."""

    def _before_recv(self) -> None:
        """Called once per receive loop (e.g. a periodic HEARTBEAT)."""

    # ---------------------------------------------------------------- loop
    def run(self, alive: Any) -> str:
        """Pump messages until the driver is done; returns how it ended."""
        assert self.conn is not None
        wall_end = time.monotonic() + self.wall_timeout_s
        setup_end_us = round(self.setup_timeout_s * 1e6)
        while self.driver.phase != "done":
            self._before_recv()
            batch = self.conn.recv(0.5)
            if not batch and not alive():
                return "sitl_exited"
            for msg in batch:
                self._handle(msg)
                if self.driver.phase == "done":
                    break
            if self.driver.route_t0_us is None and self.now.t_us > setup_end_us:
                return f"setup_timeout:{self.driver.phase}"
            if time.monotonic() > wall_end:
                return "wall_timeout"
        return self.driver.outcome

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.tlog.close()

    def _handle(self, msg: Any) -> None:
        kind = msg.get_type()
        self.rec.count(kind)
        stamp = self.feed_stamps.get(kind)
        if (stamp is not None and self.target is not None and msg.get_srcComponent() == COMPANION_COMPONENT_ID
                and self.now.t_us > 0):
            self.feed_delay_us.append(self.now.t_us - int(getattr(msg, stamp)))
        if self.target is None or (msg.get_srcSystem(), msg.get_srcComponent()) != self.target:
            return  # not the autopilot (it forwards the companion's messages between its links)
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
            elif kind == "TIMESYNC" and msg.tc1 != 0 and msg.ts1 > 0:
                self.command_delay_us.append(msg.tc1 // 1000 - msg.ts1 // 1000)
            elif kind == "COMMAND_ACK" and msg.command != MSG.MAV_CMD_SET_MESSAGE_INTERVAL:
                self.acks.append((now.t_us, int(msg.command), int(msg.result)))
                self._handle_vehicle(kind, msg)
            elif kind == "STATUSTEXT":
                rec.statustext.append((now.t_us, str(msg.text)))
            else:
                self._handle_vehicle(kind, msg)
        except CodecError as exc:
            rec.reject(exc.reason)

    def _record_truth(self, p_ned_m: np.ndarray, v_ned_m_s: np.ndarray) -> None:
        """One truth sample, stamped with the latest IMU time; drives the GNSS source."""
        if self.now.t_us == 0:
            return  # no IMU time yet to stamp it with
        g = self.source.on_truth(self.now.t_us, p_ned_m, v_ned_m_s)
        rec = self.rec
        rec.truth_t_us.append(self.now.t_us)
        rec.truth_p_ned_m.append(p_ned_m)
        rec.truth_v_ned_m_s.append(v_ned_m_s)
        rec.truth_bias_ned_m.append(g.bias_ned_m)
        rec.truth_latency_s.append(g.latency_s)
        rec.truth_clearance_m.append(g.clearance_m)
        self.now.truth_ned_m, self.now.truth_v_ned_m_s = p_ned_m, v_ned_m_s

    def _tick(self) -> None:
        t = self.now.t_us
        assert self.conn is not None
        if t >= self._next_timesync_us:
            self._next_timesync_us = t + TIMESYNC_PERIOD_US
            self.conn.send(MSG.MAVLink_timesync_message(0, t * 1000))
        for sf in self.source.due(t):
            self._send_fix(sf)
            self.gps_sent += 1
        for c in self.driver.step(self.now):
            self._send(c)

    def _command(self, command: int, *params: float) -> None:
        assert self.conn is not None and self.target is not None
        self.conn.send(MSG.MAVLink_command_long_message(*self.target, command, 0, *params))

    def _send(self, c: Command) -> None:
        if c.kind == "command_long":
            self._command(*c.args)
        elif c.kind == "setpoint":
            assert self.conn is not None and self.target is not None
            self.conn.send(MSG.MAVLink_set_position_target_local_ned_message(
                c.args[0], *self.target, MSG.MAV_FRAME_LOCAL_NED, SETPOINT_TYPE_MASK, *c.args[1:], 0.0, 0.0))
            self.setpoints_sent += 1
