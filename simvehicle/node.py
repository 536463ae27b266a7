"""The vehicle process: SimVehicle on UDP, talking MAVLink 2 to the companions and the ground.

Per control step (0.05 s of boot time) the vehicle advances :class:`SimVehicle` on the latest
ODOMETRY and setpoint it has received, then sends that period's HIGHRES_IMU and
ATTITUDE_QUATERNION (200 Hz; SIM_STATE at 50 Hz in the tick of the IMU sample it matches), the
GNSS fixes whose latency elapsed in the period (GPS_RAW_INT, ``time_usec`` = validity time),
SYSTEM_TIME and HEARTBEAT (1 Hz), and finally the lockstep step marker. In lockstep it then
waits for the companions' answers (:class:`StepBarrier`); in real time each IMU sample leaves
at its own wall-clock instant and nothing waits.

Three UDP ports: one per companion (estimator, bridge; each learns its peer from the first
valid frame, so a restarted companion is picked up again) and a ground port where the vehicle
looks like a small autopilot to QGroundControl, MAVProxy and MAVSDK (:mod:`simvehicle.groundlink`:
telemetry, parameters, commands, and every companion frame forwarded).
Every frame sent to or received from a companion goes to ``run.tlog`` once (the frames sent to
both companions are written for the estimator link only), stamped with ``epoch + t``: ``epoch``
is the wall clock when the vehicle started, ``t`` the simulated time in lockstep and the
monotonic time elapsed in real time, so stamps never go backwards and a log viewer shows the
real date (SYSTEM_TIME pairs that clock with boot time). The log starts with the vehicle's
GPS_GLOBAL_ORIGIN (the mission's home: the local frame's origin) and HOME_POSITION, as an
autopilot's log does, so a tool reading it alone knows the frame.

The vehicle's own clock is the reference for what it flies on: an ODOMETRY, setpoint or belief
stamped outside a window around it (:mod:`companion.domain.clock_guard`) is ignored and raises
an alarm (counted as ``clock_alarm_<type>``, the first one of each kind printed on stderr); so
is a belief outside [0, 1] or a negative NIS. No message can raise out of :meth:`on_message`.
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.clock_guard import ClockWindow, within
from companion.domain.samples import NavEstimate, Setpoint
from companion.domain.statistics import LATENCY_STATISTICS, describe
from companion.mavlink import codec as codec
from companion.mavlink.lockstep import LockstepConfig, step_marker
from companion.mavlink.tlog import TlogWriter
from companion.mavlink.udp_link import (
    BRIDGE_COMPONENT_ID,
    ESTIMATOR_COMPONENT_ID,
    VEHICLE_SYSTEM_ID,
    LinkConfig,
    UdpLink,
)
from companion.mission import Mission
from companion.runtime import count_handler_error, write_json
from companion.telemetry.codec import FlightStatus, GnssReport
from companion.telemetry.pubsub import DeferredPublisher, TelemetryPublisher
from simvehicle import SimVehicle
from simvehicle import ground_telemetry as gt
from simvehicle.barrier import StepBarrier
from simvehicle.groundlink import GroundConfig, ground_link_for, vehicle_status
from simvehicle.rawgnss import RawGnssModel
from simvehicle.recording import FlightRecorder
from simvehicle.ubx_server import ReceiverStream

AUTOPILOT_COMPONENT_ID = 1
COMPANIONS = ("estimator", "bridge")
MAX_JITTER_SAMPLES = 400_000  # real time: IMU send instants kept for the jitter statistics (200 Hz)
COMPANION_COMPONENTS = {"estimator": ESTIMATOR_COMPONENT_ID, "bridge": BRIDGE_COMPONENT_ID}
STATUS_PERIOD_US = 1_000_000  # vehicle/status telemetry: 1 Hz of boot time (and on a change), as HEARTBEAT
# what the vehicle flies on must be stamped near its own time (the estimate trails it by latency)
INPUT_WINDOW = ClockWindow(max_back_us=5_000_000, max_forward_us=100_000)


@dataclass(frozen=True, slots=True)
class VehicleNodeConfig:
    estimator_port: int
    bridge_port: int
    ground_port: int
    out_dir: Path
    max_duration_s: float
    realtime: bool = False
    ground_out: tuple[tuple[str, int], ...] = (("127.0.0.1", 14550),)  # udpin ground stations
    lockstep: LockstepConfig = field(default_factory=LockstepConfig)
    startup_timeout_s: float = 60.0  # wall time to wait for both companions' first HEARTBEAT
    sim_state_period_us: int = 20_000  # SIM_STATE, 50 Hz
    clock_period_us: int = 1_000_000  # SYSTEM_TIME and HEARTBEAT, 1 Hz
    progress_period_s: float = 0.25  # wall time between progress lines on stdout
    stats_period_s: float = 1.0  # wall time between vehicle.json updates (a kill -9 loses <= this)
    # the companion estimator's parameters shown on the ground link (``simvehicle.params``: EST_* names)
    estimator_params: tuple[tuple[str, float], ...] = ()
    ubx_port: int = 0  # the raw receiver's UBX TCP port (0: a free one; receiver.json names it)


@dataclass(slots=True)
class _Inbox:
    """The latest of what the companions sent (the autopilot flies on these)."""

    estimate: NavEstimate | None = None
    setpoint: Setpoint | None = None
    beta: float = math.nan
    nis: float = math.nan
    bias_ned_m: np.ndarray | None = None  # DEBUG_VECT GNSS_BIAS: the estimated GNSS bias [m]


class VehicleNode:
    def __init__(
        self,
        sim: SimVehicle,
        mission: Mission,
        recorder: FlightRecorder,
        config: VehicleNodeConfig,
        link_fields: dict[str, Any],
        rng: np.random.Generator | None,
        telemetry: TelemetryPublisher | None = None,
    ) -> None:
        self.sim = sim
        self.telemetry = telemetry or TelemetryPublisher.disabled()  # Zenoh: vehicle/truth, vehicle/gnss
        self._topics = DeferredPublisher(self.telemetry)  # published while the companions work
        self.mission = mission
        self.config = config
        self.inbox = _Inbox()
        self.counters: dict[str, int] = {}
        self.t_us = 0
        self.epoch_us = int(time.time() * 1e6)  # wall clock at start: stamp = epoch + elapsed
        self._wall0_ns = time.perf_counter_ns()
        config.out_dir.mkdir(parents=True, exist_ok=True)
        self.tlog = TlogWriter(config.out_dir / "run.tlog")
        tee = self._tee
        accept = frozenset({VEHICLE_SYSTEM_ID})
        base = {"system_id": VEHICLE_SYSTEM_ID, "component_id": AUTOPILOT_COMPONENT_ID, **link_fields}
        self.links = {
            name: UdpLink(LinkConfig(bind_port=port, accept_system_ids=accept, link_id=link_id,
                                     accept_component_ids=frozenset({COMPANION_COMPONENTS[name]}), **base),
                          rng, link_tee)
            for name, port, link_id, link_tee in (("estimator", config.estimator_port, 10, tee),
                                                  ("bridge", config.bridge_port, 11, self._tee_received))
        }
        self.ground = ground_link_for(GroundConfig(config.ground_port, config.ground_out), mission, sim,
                                      {**base, "link_id": 12}, self._boot_ns, dict(config.estimator_params))
        # run.tlog says where its local frame is, as an autopilot's log does (export and replay read it)
        home = self.ground.home
        for msg in (gt.encode_gps_global_origin(home, 0), gt.encode_home_position(home, 0)):
            self.tlog.write_frame(self._stamp_us(), codec.pack(self.ground.link.mav, msg))
        self.barrier = StepBarrier({n: self.links[n] for n in COMPANIONS}, config.lockstep)
        self.recorder = recorder
        self.imu_send_ns: list[int] = []
        self._status_sent: tuple[str, bool] | None = None
        self._next_status_us = 0
        self.gnss_sent = 0
        # the raw receiver (scenario canyon): UBX on TCP, receiver.ubx, receiver.json
        self.receiver = (ReceiverStream(sim.gnss, config.ubx_port, config.out_dir)
                         if isinstance(sim.gnss, RawGnssModel) else None)
        self.collisions = 0  # control periods that end in contact (counted on entry)

    def _publish_status(self, status: Any) -> None:
        """``vehicle/status`` (mode, armed) once a second of boot time and on every change."""
        now = (status.mode, status.armed)
        if now != self._status_sent or status.t_us >= self._next_status_us:
            self._status_sent, self._next_status_us = now, status.t_us + STATUS_PERIOD_US
            self._topics.publish("status", FlightStatus(status.t_us, status.mode, status.armed))

    # -- clocks and the tlog ---------------------------------------------------------------
    def _boot_ns(self) -> int:
        """Boot time now: simulated in lockstep, elapsed monotonic wall time in real time."""
        return time.perf_counter_ns() - self._wall0_ns if self.config.realtime else self.t_us * 1000

    def _stamp_us(self) -> int:
        return self.epoch_us + self._boot_ns() // 1000

    def _tee(self, frame: bytes, sent: bool) -> None:
        self.tlog.write_frame(self._stamp_us(), frame)

    def _tee_received(self, frame: bytes, sent: bool) -> None:
        """The bridge link sends only copies of what the estimator link sends: tee what it receives."""
        if not sent:
            self._tee(frame, sent)

    def _count(self, name: str) -> None:
        self.counters[name] = self.counters.get(name, 0) + 1

    # -- receiving -------------------------------------------------------------------------
    def on_message(self, source: str, msg: Any) -> None:
        """Handle one message; whatever it holds, it is counted and never raised."""
        try:
            self._on_message(source, msg)
        except Exception as exc:  # noqa: BLE001 - a frame must never end the flight
            count_handler_error(self.counters, "simvehicle", msg, exc)

    def _alarm(self, kind: str, t_us: int) -> None:
        """An input stamped outside the window around our own time: ignored, counted, reported."""
        name = f"clock_alarm_{kind}"
        if name not in self.counters:
            print(f"simvehicle: alarm: {kind} stamped {t_us} µs ignored at vehicle time {self.t_us} µs",
                  file=sys.stderr)
        self._count(name)

    def _on_message(self, source: str, msg: Any) -> None:
        kind = msg.get_type()
        if source == "ground":
            self._count(f"ground_{kind}")
            self.ground.handle(msg)
            return
        self.ground.forward(bytes(msg.get_msgbuf()))  # all of it: the ground sees no false loss
        try:
            if kind == "ODOMETRY":
                estimate = codec.decode_odometry(msg)
                if not within(estimate.t_us, self.t_us, INPUT_WINDOW):
                    self._alarm(kind, estimate.t_us)
                    return
                if self.inbox.estimate is None or estimate.t_us >= self.inbox.estimate.t_us:
                    self.inbox.estimate = estimate
            elif kind == "SET_POSITION_TARGET_LOCAL_NED":
                setpoint = codec.decode_setpoint(msg)
                if not within(setpoint.t_us, self.t_us, INPUT_WINDOW):
                    self._alarm(kind, setpoint.t_us)
                    return
                self.inbox.setpoint = setpoint
            elif kind == "NAMED_VALUE_FLOAT":
                value = codec.decode_named_value(msg)
                if not within(value.t_us, self.t_us, INPUT_WINDOW):
                    self._alarm(kind, value.t_us)
                    return
                if value.name == codec.BELIEF_NAME:
                    if not 0.0 <= value.value <= 1.0:
                        raise codec.CodecError("out_of_range", f"{value.name} {value.value}")
                    self.inbox.beta = value.value
                elif value.name == codec.NIS_NAME:
                    if not value.value >= 0.0:
                        raise codec.CodecError("out_of_range", f"{value.name} {value.value}")
                    self.inbox.nis = value.value
            elif kind == "DEBUG_VECT":
                self.inbox.bias_ned_m = codec.decode_bias(msg)[1]
            elif kind not in ("HEARTBEAT", "TIMESYNC", "ESTIMATOR_STATUS"):
                self._count(f"ignored_{kind}")
        except codec.CodecError as exc:
            self._count(f"rejected_{kind}_{exc.reason}")

    def poll(self) -> None:
        """Handle whatever is waiting on every link (never blocks)."""
        for name, link in (*self.links.items(), ("ground", self.ground.link)):
            for msg in link.recv_all():
                self.on_message(name, msg)

    # -- sending ---------------------------------------------------------------------------
    def _send(self, msg: Any, ground: bool = False) -> None:
        self.links["estimator"].send(msg)
        if ground:
            self.ground.send(msg)

    def _send_step(self, out: Any, pace: Callable[[int], None] | None) -> None:
        frame = self.mission.frame
        fixes = list(zip(out.gnss_arrival_us, out.gnss, strict=True))
        raws = list(out.gnss_raw)
        nan = [math.nan] * len(out.tick_us)
        hpa, temp = (nan, nan) if out.baro is None else (out.baro[1].tolist(), out.baro[2].tolist())
        for i, (imu, att, truth) in enumerate(zip(out.imu, out.attitude, out.truth, strict=True)):
            if pace is not None:
                pace(imu.t_us)
            self._send(codec.encode_attitude(att))  # attitude first: the IMU sample is rotated by it
            self._send(codec.encode_imu(imu, hpa[i], temp[i]))  # with the barometer's fields
            if imu.t_us % self.config.sim_state_period_us == 0:
                self._send(codec.encode_truth(truth, frame, self.sim.gnss.to_geodetic))
                self._topics.publish("truth", truth)
            while fixes and fixes[0][0] <= imu.t_us:
                fix = fixes.pop(0)[1]
                if self.ground.gps_disabled:  # SIM_GPS_DISABLE set from the ground: an outage
                    self._count("gnss_withheld")
                    continue
                self._send(codec.encode_gnss(fix))
                self.ground.send_gnss(fix, imu.t_us)
                self._topics.publish("gnss", GnssReport(imu.t_us, fix))
                self.gnss_sent += 1
            if raws and raws[0].arrival_us <= imu.t_us and self.receiver is not None:
                due = [raws.pop(0)]
                while raws and raws[0].arrival_us <= imu.t_us:
                    due.append(raws.pop(0))
                if self.ground.gps_disabled:  # an outage for the raw stream too
                    self._count("ubx_withheld")
                else:
                    self.receiver.send(due)
        if out.t_us % self.config.clock_period_us == 0:
            clock = codec.encode_system_time(self._stamp_us(), out.t_us)
            self._send(clock, ground=True)
            self.links["bridge"].send(clock)
            beat = self.ground.heartbeat()  # the ground link sends its own on its schedule
            self._send(beat)
            self.links["bridge"].send(beat)

    def _pace(self, wall0_ns: int) -> Callable[[int], None]:
        def pace(t_us: int) -> None:
            target = wall0_ns + t_us * 1000
            while (now := time.perf_counter_ns()) < target:
                if target - now > 1_500_000:
                    self.poll()
                    time.sleep(min((target - now) / 1e9 - 0.001, 0.001))
            self.imu_send_ns.append(time.perf_counter_ns())
            if len(self.imu_send_ns) > MAX_JITTER_SAMPLES:  # bounded: the latest half-hour is kept
                del self.imu_send_ns[: MAX_JITTER_SAMPLES // 2]

        return pace

    # -- the flight ------------------------------------------------------------------------
    def wait_for_companions(self) -> None:
        """Lockstep needs both companions: wait for their first HEARTBEAT (they learn nothing
        from us until then; we learn their address from it)."""
        deadline = time.monotonic() + self.config.startup_timeout_s
        seen: set[str] = set()
        while seen != set(COMPANIONS):
            if time.monotonic() > deadline:
                missing = ", ".join(sorted(set(COMPANIONS) - seen))
                raise TimeoutError(f"no HEARTBEAT from {missing} within {self.config.startup_timeout_s} s")
            for name in COMPANIONS:
                if self.links[name].recv(timeout_s=0.05):
                    seen.add(name)
            for msg in self.ground.link.recv_all():
                self.on_message("ground", msg)

    def fly(self) -> dict[str, Any]:
        cfg = self.config
        self.wait_for_companions()
        max_t_us = round(cfg.max_duration_s * 1e6)
        wall0 = time.perf_counter_ns()
        if cfg.realtime:  # boot time 0 is now; the stamp clock moves on from the same monotonic base
            self.epoch_us += (wall0 - self._wall0_ns) // 1000
        self._wall0_ns = wall0
        pace = self._pace(wall0) if cfg.realtime else None
        next_progress = next_stats = 0.0
        outcome = "timeout"
        was_collided = False
        while self.t_us < max_t_us:
            out = self.sim.advance(self.inbox.estimate, self.inbox.setpoint)
            self.t_us = out.t_us
            if not cfg.realtime:
                for name in COMPANIONS:
                    self.links[name].begin_batch()
                self.ground.link.begin_batch()  # lockstep: the step's ground traffic in one datagram
            self._send_step(out, pace)
            if cfg.realtime:
                for name in COMPANIONS:
                    self.links[name].send(step_marker(out.t_us))
                self.poll()
                self._topics.drain()
            else:
                self.barrier.wait(out.t_us, self.on_message, {"ground": self.ground.link}, self._topics.drain)
            row = self.recorder.record(out, self.inbox.estimate, self.inbox.setpoint, self.inbox.beta,
                                       self.inbox.nis, self.inbox.bias_ned_m)
            status = vehicle_status(self.sim, out, self.ground.gnss_flowing(out.t_us))
            self.ground.tick(status)
            self._publish_status(status)
            if out.collided and not was_collided:
                self.collisions += 1
                self.ground.collision(out.t_us)
            was_collided = out.collided
            reached = self.recorder.reached_goal()
            if reached:
                outcome = "reached_goal"
                self.ground.goal_reached(out.t_us)
            self.ground.link.flush()  # (no batch in real time: nothing to send)
            if reached:
                break
            if time.monotonic() >= next_progress:
                next_progress = time.monotonic() + cfg.progress_period_s
                print(json.dumps({"t_s": out.t_us / 1e6, "goal_distance_m": row.goal_distance_m}), flush=True)
            if time.monotonic() >= next_stats:
                next_stats = time.monotonic() + cfg.stats_period_s
                self.recorder.flush()  # the record so far is on disk: a kill -9 loses <= 1 s of it
                self.write_stats({"outcome": "running", "t_s": self.t_us / 1e6})
        return {"outcome": outcome, "t_s": self.t_us / 1e6, "wall_s": (time.perf_counter_ns() - wall0) / 1e9}

    def write_stats(self, result: dict[str, Any]) -> None:
        """``vehicle.json``: the result so far and every counter (atomic: never half a file)."""
        write_json(self.config.out_dir / "vehicle.json", {**result, **self.stats()})

    def stats(self) -> dict[str, Any]:
        periods_ms = np.diff(np.asarray(self.imu_send_ns, dtype=float)) / 1e6
        period_ms = self.sim.config.vehicle.physics_dt_us / 1000
        jitter = np.abs(periods_ms - period_ms)
        return {
            "links": {name: link.counters.as_dict() for name, link in self.links.items()},
            "ground": self.ground.link.counters.as_dict(),
            "ground_requests": {**self.ground.counters, **self.ground.params.counters},
            "node": dict(self.counters),
            "gnss_sent": self.gnss_sent,
            **({"ubx": dict(self.receiver.server.counters, url=self.receiver.server.url)}
               if self.receiver is not None else {}),
            "collisions": self.collisions,
            "telemetry": self.telemetry.counters(),
            "lockstep": dict(self.barrier.counters),
            "imu_period_jitter_ms": describe(jitter, LATENCY_STATISTICS),
        }

    def close(self) -> None:
        """Flush what was recorded (also on SIGTERM): tlog, time series, statistics."""
        self.tlog.close()
        if self.receiver is not None:
            self.receiver.close()
        self.recorder.save(self.config.out_dir / "vehicle_series.npz")
        for link in self.links.values():
            link.close()
        self.ground.close()
        self.telemetry.close()
