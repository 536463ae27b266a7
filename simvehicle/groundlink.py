"""The vehicle's ground link: how QGroundControl, MAVProxy and MAVSDK see a small autopilot.

One UDP socket bound to the ground port serves every ground client at once:

- ``udpout`` clients (``mavproxy.py --master=udpout:127.0.0.1:PORT``, MAVSDK
  ``udpout://127.0.0.1:PORT``) send to the ground port; each address whose HEARTBEAT was
  accepted within ``client_timeout_s`` receives everything the vehicle sends (other frames
  cannot add a destination);
- ``udpin`` clients listen on a port of their own: the vehicle sends to the configured
  ``--ground-out`` targets (default 127.0.0.1:14550, where QGroundControl and MAVProxy listen)
  from the ground port, so their replies come back to it.

Telemetry is scheduled on boot time (so a lockstep run sends the same stream as a real-time
one): HEARTBEAT (armed, custom mode), SYS_STATUS, EXTENDED_SYS_STATE, GLOBAL_POSITION_INT,
LOCAL_POSITION_NED, ATTITUDE, ATTITUDE_QUATERNION, VFR_HUD, HOME_POSITION and GPS_GLOBAL_ORIGIN
at the periods of :data:`STREAMS`; SET_MESSAGE_INTERVAL changes them. Events go out as
STATUSTEXT. Requests are answered: TIMESYNC, PING, the parameter protocol (:mod:`simvehicle.params`)
and COMMAND_LONG (COMMAND_ACK to the requester's system and component). Every frame the
companions send is forwarded unchanged (their sequence numbers stay continuous, so a ground
station's link statistics count no false loss). The ground link is not written to ``run.tlog``,
which holds the companion links (what the estimator was given and what the companions answered).
"""

from __future__ import annotations

import argparse
import math
import socket
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from companion.domain.samples import GnssFix
from companion.errors import UserError
from companion.mavlink import codec
from companion.mavlink.udp_link import IP_RECVERR, LinkConfig, UdpLink
from simvehicle import ground_telemetry as gt
from simvehicle.params import GPS_DISABLE, ParamServer

Address = tuple[str, int]
QGC_DEFAULT_PORT = 14550
GNSS_STALE_US = 1_000_000  # GPS unhealthy after this long without a fix sent
MAX_CLIENTS = 16  # udpout clients remembered at once (the oldest is forgotten first)

_M = mavlink
STREAMS = {  # message id -> default period (µs of boot time); served at most once per control period
    _M.MAVLINK_MSG_ID_HEARTBEAT: 1_000_000,
    _M.MAVLINK_MSG_ID_SYS_STATUS: 1_000_000,
    _M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1_000_000,
    _M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 100_000,
    _M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 100_000,
    _M.MAVLINK_MSG_ID_ATTITUDE: 100_000,
    _M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 100_000,
    _M.MAVLINK_MSG_ID_VFR_HUD: 250_000,
    _M.MAVLINK_MSG_ID_HOME_POSITION: 5_000_000,
    _M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: 10_000_000,
}


@dataclass(frozen=True, slots=True)
class GroundConfig:
    bind_port: int  # the ground port (udpout clients send here)
    out_targets: tuple[Address, ...] = (("127.0.0.1", QGC_DEFAULT_PORT),)  # udpin listeners
    client_timeout_s: float = 10.0  # a udpout client silent this long is no longer sent to
    streams_us: dict[int, int] = field(default_factory=lambda: dict(STREAMS))


DEFAULT_GROUND_OUT = f"127.0.0.1:{QGC_DEFAULT_PORT}"


def parse_ground_out(text: str) -> Address:
    """``HOST:PORT`` (or just ``PORT`` on 127.0.0.1) -> address; a UserError names a bad one."""
    host, _, port = text.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 < number < 65536:
        raise UserError(f"--ground-out: expected HOST:PORT, got {text!r}")
    return (host or "127.0.0.1", number)


def add_ground_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--ground-out", action="append", metavar="HOST:PORT",
        help=f"also send the ground telemetry to a listening (udpin) ground station here; repeatable "
             f"(default {DEFAULT_GROUND_OUT}, where QGroundControl and MAVProxy listen)")
    parser.add_argument("--no-ground-out", action="store_true",
                        help="send only to ground stations that connect to the ground port (udpout)")


def ground_out_arguments(args: argparse.Namespace) -> list[str]:
    """The same choice as vehicle command-line flags (for a launcher)."""
    if args.no_ground_out:
        return ["--no-ground-out"]
    return [flag for target in args.ground_out or () for flag in ("--ground-out", target)]


def ground_out_targets(args: argparse.Namespace) -> tuple[Address, ...]:
    if args.no_ground_out:
        return ()
    return tuple(parse_ground_out(t) for t in (args.ground_out or [DEFAULT_GROUND_OUT]))


class MultiPeerLink(UdpLink):
    """A :class:`UdpLink` whose datagrams go to every destination: fixed targets plus the
    clients heard recently. Each frame is packed once (one sequence number) for all of them."""

    def __init__(self, config: LinkConfig, targets: tuple[Address, ...], client_timeout_s: float) -> None:
        super().__init__(config)
        # No ICMP errors: a target nobody listens on (14550 without a ground station) would
        # otherwise fail the next send, the one to a live client.
        self._sock.setsockopt(socket.IPPROTO_IP, IP_RECVERR, 0)
        self.targets = targets
        self.client_timeout_s = client_timeout_s
        self.clients: dict[Address, float] = {}  # address -> time.monotonic() last heard

    def destinations(self) -> list[Address]:
        now = time.monotonic()
        alive = [a for a, t in self.clients.items() if now - t <= self.client_timeout_s]
        return [*self.targets, *(a for a in alive if a not in self.targets)]

    def _accept(self, msgs: list[Any], addr: tuple[str, int]) -> list[Any]:
        accepted = super()._accept(msgs, addr)
        if any(m.get_type() == "HEARTBEAT" for m in accepted):  # a client announces itself
            self.clients.pop(addr, None)
            self.clients[addr] = time.monotonic()
            while len(self.clients) > MAX_CLIENTS:
                del self.clients[next(iter(self.clients))]
        return accepted

    def _transmit(self, frames: list[bytes]) -> None:
        for dest in self.destinations():
            self.peer = dest
            super()._transmit(frames)

    def send(self, msg: mavlink.MAVLink_message) -> None:
        self._send_datagram(self.pack(msg))  # signed when the link has a key
        self.counters.messages_tx += 1

    def send_frame(self, frame: bytes) -> None:
        self._send_datagram(frame)
        self.counters.messages_tx += 1


@dataclass(slots=True)
class _Events:
    """Previous state, to report changes once (at start both are not OK yet: the first
    estimate and fix are reported as they come, not a loss before them)."""

    estimate_ok: bool = False
    gnss_ok: bool = False


class GroundLink:
    """Ground-station side of the vehicle (see the module docstring)."""

    def __init__(self, config: GroundConfig, link_fields: dict[str, Any], params: ParamServer,
                 home: gt.Home, clock_ns: Callable[[], int]) -> None:
        self.config = config
        self.params = params
        self.home = home
        self.clock_ns = clock_ns  # the vehicle's boot clock (ns), answers TIMESYNC
        self.link = MultiPeerLink(LinkConfig(bind_port=config.bind_port, **link_fields), config.out_targets,
                                  config.client_timeout_s)
        self.system_id = self.link.config.system_id
        self.component_id = self.link.config.component_id
        self.periods_us = dict(config.streams_us)
        self._due_us = dict.fromkeys(self.periods_us, 0)
        self.status: gt.VehicleStatus | None = None
        self._events = _Events()
        self._last_fix_us = -GNSS_STALE_US - 1
        self.counters: dict[str, int] = {}

    # -- plumbing ---------------------------------------------------------------------------
    def fileno(self) -> int:
        return self.link.fileno()

    def close(self) -> None:
        self.link.close()

    def _count(self, name: str) -> None:
        self.counters[name] = self.counters.get(name, 0) + 1

    def send(self, msg: mavlink.MAVLink_message) -> None:
        self.link.send(msg)

    def forward(self, frame: bytes) -> None:
        """A companion's frame, unchanged (its ids, sequence number and signature stay)."""
        self.link.send_frame(frame)

    @property
    def gps_disabled(self) -> bool:
        return self.params.value(GPS_DISABLE) >= 0.5

    def send_gnss(self, fix: GnssFix, t_us: int) -> None:
        self._last_fix_us = t_us
        self.send(codec.encode_gnss(fix))

    def gnss_flowing(self, t_us: int) -> bool:
        return not self.gps_disabled and t_us - self._last_fix_us <= GNSS_STALE_US

    def event(self, severity: int, text: str) -> None:
        self._count("statustext")
        self.send(gt.encode_statustext(severity, text))

    def collision(self, t_us: int) -> None:
        self.event(_M.MAV_SEVERITY_CRITICAL, f"Collision at t={t_us / 1e6:.1f} s")

    def goal_reached(self, t_us: int) -> None:
        self.event(_M.MAV_SEVERITY_NOTICE, f"Goal reached at t={t_us / 1e6:.1f} s")

    # -- telemetry --------------------------------------------------------------------------
    def heartbeat(self) -> mavlink.MAVLink_heartbeat_message:
        s = self.status
        return codec.encode_heartbeat("vehicle", armed=s is None or s.armed,
                                      mode=None if s is None else s.mode)

    def _message(self, msgid: int) -> mavlink.MAVLink_message | None:
        """The message ``msgid`` as of now, None if we cannot send it (yet)."""
        s, home = self.status, self.home
        t_us = 0 if s is None else s.t_us
        if msgid == _M.MAVLINK_MSG_ID_HEARTBEAT:
            return self.heartbeat()
        if msgid == _M.MAVLINK_MSG_ID_HOME_POSITION:
            return gt.encode_home_position(home, t_us)
        if msgid == _M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN:
            return gt.encode_gps_global_origin(home, t_us)
        if msgid == _M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            return gt.encode_extended_sys_state()
        if msgid == _M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return gt.encode_autopilot_version()
        if s is None:
            return None
        c = self.link.counters
        encoders: dict[int, Callable[[], mavlink.MAVLink_message]] = {
            _M.MAVLINK_MSG_ID_SYS_STATUS: lambda: gt.encode_sys_status(s, min(65535, c.garbage + c.bad_crc)),
            _M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: lambda: gt.encode_global_position(s, home),
            _M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: lambda: gt.encode_local_position(s),
            _M.MAVLINK_MSG_ID_ATTITUDE: lambda: gt.encode_attitude_euler(s),
            _M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: lambda: gt.encode_attitude_quaternion(s),
            _M.MAVLINK_MSG_ID_VFR_HUD: lambda: gt.encode_vfr_hud(s, home),
        }
        make = encoders.get(msgid)
        return None if make is None else make()

    def tick(self, status: gt.VehicleStatus) -> None:
        """Once per control period: report state changes, then send what is due."""
        self.status = status
        self._report_changes(status)
        for msgid, period in self.periods_us.items():
            if period <= 0 or status.t_us < self._due_us[msgid]:
                continue
            self._due_us[msgid] = (status.t_us // period + 1) * period
            msg = self._message(msgid)
            if msg is not None:
                self.send(msg)

    def _report_changes(self, s: gt.VehicleStatus) -> None:
        ev = self._events
        if ev.estimate_ok and not s.estimate_ok:
            self.event(_M.MAV_SEVERITY_CRITICAL, "Estimator lost: holding position")
        elif s.estimate_ok and not ev.estimate_ok:
            self.event(_M.MAV_SEVERITY_NOTICE, "Estimator OK: following setpoints")
        if ev.gnss_ok and not s.gnss_ok:
            why = " (SIM_GPS_DISABLE)" if self.gps_disabled else ""
            self.event(_M.MAV_SEVERITY_WARNING, f"GNSS lost{why}")
        elif s.gnss_ok and not ev.gnss_ok:
            self.event(_M.MAV_SEVERITY_NOTICE, "GNSS OK")
        ev.estimate_ok, ev.gnss_ok = s.estimate_ok, s.gnss_ok

    # -- requests ---------------------------------------------------------------------------
    def handle(self, msg: Any) -> None:
        """One message from a ground client."""
        kind = msg.get_type()
        if kind == "TIMESYNC":
            if int(msg.tc1) == 0:  # a request: answer with our clock, mirror theirs
                self.send(mavlink.MAVLink_timesync_message(tc1=max(1, self.clock_ns()), ts1=int(msg.ts1)))
        elif kind in ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET"):
            answers, note = self.params.handle(msg)
            for answer in answers:
                self.send(answer)
            if note is not None:
                self.event(_M.MAV_SEVERITY_INFO if "set to" in note else _M.MAV_SEVERITY_WARNING, note)
        elif kind == "COMMAND_LONG":
            self._command(msg)
        elif kind == "PING" and int(msg.target_system) == 0:  # a request: answer to its sender
            self.send(mavlink.MAVLink_ping_message(int(msg.time_usec), int(msg.seq), msg.get_srcSystem(),
                                                   msg.get_srcComponent()))

    def _command(self, msg: Any) -> None:
        if int(msg.target_system) not in (0, self.system_id):
            self._count("command_not_for_us")
            return
        command = int(msg.command)
        result, then = self._run_command(command, msg)
        requester = (msg.get_srcSystem(), msg.get_srcComponent())
        self.send(mavlink.MAVLink_command_ack_message(command, result, 0, 0, *requester))
        if then is not None:
            self.send(then)

    def _run_command(self, command: int, m: Any) -> tuple[int, mavlink.MAVLink_message | None]:
        """(MAV_RESULT, message to send after the ACK or None)."""
        accepted, denied = _M.MAV_RESULT_ACCEPTED, _M.MAV_RESULT_DENIED
        unsupported = _M.MAV_RESULT_UNSUPPORTED
        if command == _M.MAV_CMD_REQUEST_MESSAGE:
            reply = self._message(_msgid(m.param1))
            return (accepted, reply) if reply is not None else (unsupported, None)
        if command == _M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return accepted, gt.encode_autopilot_version()
        if command == _M.MAV_CMD_GET_HOME_POSITION:
            return accepted, self._message(_M.MAVLINK_MSG_ID_HOME_POSITION)
        if command == _M.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._set_interval(_msgid(m.param1), float(m.param2)), None
        if command == _M.MAV_CMD_COMPONENT_ARM_DISARM:
            # the simulated flight starts in the air and never lands: arming is a no-op, disarming refused
            return (accepted if float(m.param1) == 1.0 else denied), None
        if command == _M.MAV_CMD_DO_SET_MODE:
            wanted = (_msgid(m.param2) << 16) | (_msgid(m.param3) << 24)
            current = codec.CUSTOM_MODES[self.status.mode if self.status else "OFFBOARD"]
            return (accepted if wanted == current else denied), None  # the companion picks the mode
        return unsupported, None

    def _set_interval(self, msgid: int, interval_us: float) -> int:
        if msgid not in STREAMS:
            return _M.MAV_RESULT_UNSUPPORTED
        if not math.isfinite(interval_us):
            return _M.MAV_RESULT_DENIED
        if interval_us == 0:
            period = STREAMS[msgid]  # default rate
        elif interval_us < 0:
            period = 0  # disabled
        else:
            period = max(1, min(round(interval_us), 2**31))
        self.periods_us[msgid] = period
        self._due_us[msgid] = 0 if self.status is None else self.status.t_us
        return _M.MAV_RESULT_ACCEPTED


def _msgid(param: float) -> int:
    return int(param) if math.isfinite(param) and param >= 0 else -1


def vehicle_status(sim: Any, out: Any, gnss_ok: bool) -> gt.VehicleStatus:
    """The autopilot's view at the end of control period ``out`` of ``sim`` (a SimVehicle).

    Throttle is the period's mean measured specific force along body -z times the mass over
    the maximum thrust (what the motors delivered, drag included)."""
    ap, vehicle = sim.autopilot, sim.config.vehicle
    thrust_n = -float(np.mean(out.acc_frd_m_s2[:, 2])) * vehicle.mass_kg
    holding = bool(ap.holding)
    return gt.VehicleStatus(
        t_us=int(out.t_us), p_ned_m=np.array(ap.nav_p_ned_m, dtype=float),
        v_ned_m_s=np.array(ap.nav_v_ned_m_s, dtype=float), q_ned_frd=np.asarray(out.q_ned_frd[-1]),
        rates_frd_rad_s=np.array(sim.body.x[10:13], dtype=float),
        thrust_fraction=max(0.0, thrust_n / vehicle.max_thrust_n), armed=True,
        mode="HOLD" if holding else "OFFBOARD", estimate_ok=not holding, gnss_ok=gnss_ok,
    )


def ground_link_for(config: GroundConfig, mission: Any, sim: Any, link_fields: dict[str, Any],
                    clock_ns: Callable[[], int], estimator_params: Mapping[str, float] | None = None
                    ) -> GroundLink:
    """The ground link of a vehicle flying ``mission`` with ``sim``: parameters from the companion
    estimator's values (``EST_*``, given by whoever started both) and the vehicle's GNSS model, home
    under the flight's start."""
    from simvehicle.params import vehicle_params

    fields = {k: v for k, v in link_fields.items() if not k.startswith("drop_")}  # no loss injection
    params = ParamServer(vehicle_params(estimator_params or {}, sim.config.gnss),
                         int(fields.get("system_id", 1)), int(fields.get("component_id", 1)))
    home_ned_m = np.array([sim.start_ned_m[0], sim.start_ned_m[1], 0.0])
    return GroundLink(config, fields, params, gt.Home(mission.frame, home_ned_m), clock_ns)
