"""The companion process beside a foreign autopilot: ``python -m companion estimator --master URL``
(= ``beliefnav companion``).

Order of events: open the connection (nothing is sent before discovery); the autopilot's first
HEARTBEAT gives its system and component; from then on we send our HEARTBEAT (1 Hz, as
MAV_TYPE_ONBOARD_CONTROLLER with the autopilot's system id and our component id), TIMESYNC
requests (1 Hz) and answers, and ask for the streams. The local frame is fixed at the first good
fix: ``--home`` if given, else the autopilot's GPS_GLOBAL_ORIGIN, else its HOME_POSITION, else that
fix; the Navigator starts there. Samples (one boot-time base, :mod:`.translate`) go to the
Navigator in arrival order; the estimate is kept at 25 Hz for the comparison with the autopilot's
own estimate and fed back (``--feed``) on the estimate's clock. With ``vision``/``odometry`` our
positions are local NED about our frame's origin, which must be the autopilot's EKF origin: while
the autopilot reports no GPS_GLOBAL_ORIGIN (no GPS of its own), we set it to our frame's origin
with SET_GPS_GLOBAL_ORIGIN once a second (``--home`` fixes that frame from the start). A reboot of
the autopilot (its boot time going back) starts a fresh Navigator in the same frame and asks for
the streams again.

Outputs in ``--out DIR``: ``run.tlog`` (every frame both ways) and ``summary.json`` (written on
exit, also after Ctrl-C/SIGTERM or an error).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from companion.autopilot import compare, feeds
from companion.autopilot.connection import MavConnection, open_connection
from companion.autopilot.discovery import Discovery, DiscoveryConfig
from companion.autopilot.options import DEFAULT_COMPONENT_ID, FEEDS
from companion.autopilot.streams import StreamRates, data_stream_requests, interval_requests
from companion.autopilot.timesync import Timesync, TimesyncConfig
from companion.autopilot.translate import TranslateConfig, Translator, boot_stamp_us
from companion.domain.geodesy import LocalNedFrame, parse_home
from companion.domain.samples import GnssFix, ImuSample, NavEstimate
from companion.errors import UserError
from companion.estimator import DEFAULT_METHOD, EstimatorConfig, Navigator, check_method
from companion.mavlink import codec
from companion.telemetry.pubsub import EstimatorTelemetry, TelemetryPublisher
from companion.wiring import navigator_for

EPOCH_STRIDE_US = 10**13  # series time key = epoch (reboots) * this + boot µs: monotonic across reboots
MIN_FIX_TYPE = 3
REASK_MIN_S = 2.0  # a reboot seen this soon after asking for the streams does not ask again


@dataclass(frozen=True, slots=True)
class CompanionConfig:
    master: str  # connection string (companion.autopilot.connection)
    out_dir: Path
    method: str = DEFAULT_METHOD
    feed: str = "none"  # one of FEEDS
    home: LocalNedFrame | None = None  # None: GPS_GLOBAL_ORIGIN, else HOME_POSITION, else first good fix
    duration_s: float | None = None  # wall seconds to run; None: until interrupted
    component_id: int = DEFAULT_COMPONENT_ID
    discovery_timeout_s: float = 60.0  # wall seconds without an autopilot HEARTBEAT = error
    heartbeat_period_s: float = 1.0  # our HEARTBEAT (wall clock)
    series_period_us: int = 40_000  # our estimate kept at 25 Hz (boot time) for the comparison
    max_gap_us: int = 200_000  # no comparison across a longer hole in our series
    rates: StreamRates = field(default_factory=StreamRates)
    translate: TranslateConfig = field(default_factory=TranslateConfig)
    feeds: feeds.FeedConfig = field(default_factory=feeds.FeedConfig)
    discovery: DiscoveryConfig = field(default_factory=DiscoveryConfig)
    timesync: TimesyncConfig = field(default_factory=TimesyncConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)

    def __post_init__(self) -> None:
        check_method(self.method)
        if self.feed not in FEEDS:
            raise UserError(f"--feed {self.feed!r}: choose from {', '.join(FEEDS)}")
        if not 1 <= self.component_id <= 255:
            raise UserError(f"--component-id {self.component_id}: must be 1..255")
        if self.duration_s is not None and not self.duration_s > 0:
            raise UserError(f"--duration-s {self.duration_s}: must be positive")


@dataclass(slots=True)
class _Series:
    """Our estimate (25 Hz) and the autopilot's, keyed by epoch-offset boot time."""

    t_us: list[int] = field(default_factory=list)
    p_ned_m: list[np.ndarray] = field(default_factory=list)
    beta: list[float] = field(default_factory=list)
    global_t_us: list[int] = field(default_factory=list)
    global_lla: list[tuple[float, float, float]] = field(default_factory=list)
    local_t_us: list[int] = field(default_factory=list)
    local_ned_m: list[tuple[float, float, float]] = field(default_factory=list)

    def trim(self) -> None:
        """Equal lengths in each group again: SIGTERM (SystemExit) can land between two appends."""
        groups = (("t_us", "p_ned_m", "beta"), ("global_t_us", "global_lla"), ("local_t_us", "local_ned_m"))
        for group in groups:
            n = min(len(getattr(self, name)) for name in group)
            for name in group:
                del getattr(self, name)[n:]


class AutopilotCompanion:
    """Everything but the socket loop: handle(msg) and tick(now) (testable without a network)."""

    def __init__(self, config: CompanionConfig, conn: MavConnection,
                 telemetry: TelemetryPublisher | None = None) -> None:
        self.config = config
        self.conn = conn
        self.discovery = Discovery(config.discovery)
        self.translator = Translator(config.translate)
        self.timesync = Timesync(config.timesync)
        self.telemetry = telemetry or TelemetryPublisher.disabled()
        self._topics = EstimatorTelemetry(self.telemetry)
        self.nav: Navigator | None = None
        self.frame: LocalNedFrame | None = None
        self.home_source = ""
        self.origins: dict[str, tuple[float, float, float]] = {}
        self.counters: Counter[str] = Counter()
        self.received: Counter[str] = Counter()
        self.acks: Counter[str] = Counter()
        self.past_nav_counters: Counter[str] = Counter()
        self.series = _Series()
        self.epoch = 0
        self.errors: list[str] = []
        self._next_series_us = 0
        self._next_feed_us = 0
        self._next_heartbeat_s = 0.0
        self._next_timesync_s = 0.0
        self._ask_streams = False
        self._asked_s = math.nan
        self._fallback_sent = False
        self._last_imu_s = math.nan
        self._heartbeat_was_lost = False
        self._delay_param: str | None = None
        self._next_origin_s = 0.0

    # -- incoming -----------------------------------------------------------------------------
    def handle(self, msg: Any, now_s: float) -> None:
        """Handle one message; whatever it holds, count it and never raise."""
        try:
            self._handle(msg, now_s)
        except Exception as exc:  # noqa: BLE001 - a frame must never end the process
            name = f"handler_error_{msg.get_type()}_{type(exc).__name__}"
            if name not in self.counters:
                print(f"companion: {msg.get_type()} raised {type(exc).__name__}: {exc}", file=sys.stderr)
                self.errors.append(f"{msg.get_type()}: {type(exc).__name__}: {exc}")
            self.counters[name] += 1

    def _handle(self, msg: Any, now_s: float) -> None:
        was_known = self.discovery.autopilot is not None
        if not self.discovery.accept(msg, now_s):
            return
        kind = msg.get_type()
        self.received[kind] += 1
        if not was_known:
            ap = self.discovery.autopilot
            assert ap is not None
            self.conn.set_source(ap.system_id, self.config.component_id)
            self._ask_streams = True
            self._delay_param = self.translator.delay_parameter(ap.autopilot_type)
            if self._delay_param is not None:
                self.conn.send(mavlink.MAVLink_param_request_read_message(
                    ap.system_id, ap.component_id, self._delay_param.encode(), -1))
            self._next_heartbeat_s = self._next_timesync_s = now_s
        stamp = boot_stamp_us(msg)
        if stamp is not None and self.discovery.boot_time(stamp):
            self._rebooted(now_s)
        if kind == "TIMESYNC":
            answer = self.timesync.handle(msg, time.monotonic_ns())
            if answer is not None:
                self.conn.send(answer)
        elif kind == "COMMAND_ACK":
            self.acks[f"{_enum('MAV_CMD', msg.command)}:{_enum('MAV_RESULT', msg.result)}"] += 1
        elif kind == "PARAM_VALUE":
            ap = self.discovery.autopilot
            if ap is not None and self._delay_param is not None and msg.param_id == self._delay_param:
                self.translator.delay_parameter_value(ap.autopilot_type, msg.param_id, float(msg.param_value))
        elif kind == "SYSTEM_TIME":
            self.translator.system_time(msg)
        elif kind == "GPS_GLOBAL_ORIGIN" or kind == "HOME_POSITION":  # degE7, mm AMSL
            lla = (msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3)
            if _plausible(*lla):
                self.origins[kind] = lla
                self._check_origin(kind, lla)
            else:
                self.counters[f"rejected_{kind.lower()}"] += 1
        elif kind == "GLOBAL_POSITION_INT":
            self._reference_global(msg)
        elif kind == "LOCAL_POSITION_NED":
            p = (float(msg.x), float(msg.y), float(msg.z))
            if all(math.isfinite(v) for v in p):
                self.series.local_t_us.append(self._key(int(msg.time_boot_ms) * 1000))
                self.series.local_ned_m.append(p)
            else:
                self.counters["rejected_local_position_ned"] += 1
        else:
            sample = self.translator.sample(msg)
            if sample is not None:
                self._push(sample, now_s)

    def _reference_global(self, msg: Any) -> None:
        if msg.lat == 0 and msg.lon == 0:  # ArduPilot before its EKF has a position
            self.counters["reference_without_position"] += 1
            return
        if not _plausible(msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1e3):
            self.counters["rejected_global_position_int"] += 1
            return
        self.series.global_t_us.append(self._key(int(msg.time_boot_ms) * 1000))
        self.series.global_lla.append((msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1e3))

    def _key(self, t_us: int) -> int:
        return self.epoch * EPOCH_STRIDE_US + t_us

    def _push(self, sample: Any, now_s: float) -> None:
        if self.nav is None:
            if not (isinstance(sample, GnssFix) and sample.fix_type >= MIN_FIX_TYPE):
                self.counters["samples_before_first_fix"] += 1
                return
            self._start_navigator(sample)
            assert self.nav is not None
        self.nav.push(sample)
        if isinstance(sample, ImuSample):
            self._last_imu_s = now_s
            self._after_imu(sample.t_us)

    def _start_navigator(self, fix: GnssFix) -> None:
        if self.frame is None:
            c = self.config
            if c.home is not None:
                self.frame, self.home_source = c.home, "option --home"
            else:
                for source in ("GPS_GLOBAL_ORIGIN", "HOME_POSITION"):
                    if source in self.origins:
                        self.frame, self.home_source = LocalNedFrame(*self.origins[source]), source
                        break
                else:
                    self.frame = LocalNedFrame(fix.lat_deg, fix.lon_deg, fix.alt_m)
                    self.home_source = "first good fix"
        self.nav = navigator_for(None, self.config.method, config=self.config.estimator, frame=self.frame)
        self._topics = EstimatorTelemetry(self.telemetry)

    def _after_imu(self, t_us: int) -> None:
        assert self.nav is not None
        self._topics.update(t_us, self.nav)
        due_series, due_feed = t_us >= self._next_series_us, (
            self.config.feed != "none" and t_us >= self._next_feed_us)
        if not (due_series or due_feed):
            return
        est = self.nav.estimate()
        if est is None:
            return
        if due_series:
            self._next_series_us = t_us + self.config.series_period_us
            s = self.series
            s.t_us.append(self._key(est.t_us))
            s.p_ned_m.append(np.asarray(est.p_ned_m, dtype=float))
            s.beta.append(float(est.beta))
        if due_feed:
            # on a fixed cadence (next = previous + period), not "period after the IMU sample that
            # was due": at 50 Hz IMU that would add up to 20 ms to every period
            period = self.config.feeds.period_us(self.config.feed)
            nxt = self._next_feed_us + period
            self._next_feed_us = nxt if nxt > t_us else t_us + period
            self._send_feed(est)

    def _send_feed(self, est: NavEstimate) -> None:
        tr, feed = self.translator, self.config.feed
        if feed == "gps-input":
            assert self.frame is not None
            fix = tr.last_fix
            # GPS time on the AUTOPILOT's clock (its SYSTEM_TIME), at the estimate's time: its jitter
            # correction maps these stamps to its clock, which need not run at wall speed (SITL)
            offset_us = tr.unix_minus_boot_us
            msg: Any = feeds.gps_input(est, self.frame, self.config.feeds,
                                       hdop=fix.hdop if fix else math.nan,
                                       satellites=_known_satellites(fix),
                                       unix_s=None if offset_us is None else (est.t_us + offset_us) * 1e-6)
        elif tr.last_attitude is None or tr.last_imu is None:
            return
        elif feed == "vision":
            msg = feeds.vision_position(est, tr.last_attitude.q_ned_frd, self.config.feeds)
        else:
            msg = feeds.odometry(est, tr.last_attitude.q_ned_frd, tr.last_imu.gyro_frd_rad_s,
                                 self.config.feeds)
        self.conn.send(msg)
        self.counters[f"feed_{msg.get_type().lower()}_sent"] += 1

    def _rebooted(self, now_s: float) -> None:
        self.counters["autopilot_reboots"] += 1
        if self.nav is not None:
            self.past_nav_counters.update(self.nav.counters())
        self.nav = None
        self.epoch += 1
        self._next_series_us = self._next_feed_us = 0
        self.translator.reset()
        # asked already since it came back (its HEARTBEAT returned first)? then once is enough
        self._ask_streams = not now_s - self._asked_s < REASK_MIN_S

    # -- periodic -----------------------------------------------------------------------------
    def tick(self, now_s: float) -> None:
        if self.discovery.autopilot is None:
            return
        ap = self.discovery.autopilot
        if self.discovery.heartbeat_lost(now_s):
            self._heartbeat_was_lost = True
        elif self._heartbeat_was_lost:  # it is back (a reboot or the link): ask again
            self._heartbeat_was_lost = False
            self.counters["heartbeat_returned"] += 1
            self._ask_streams = True
        if now_s >= self._next_heartbeat_s:
            self._next_heartbeat_s = now_s + self.config.heartbeat_period_s
            self.conn.send(codec.encode_heartbeat("companion"))
        if now_s >= self._next_timesync_s:
            self._next_timesync_s = now_s + self.config.timesync.request_period_s
            self.conn.send(self.timesync.request(time.monotonic_ns()))
        self._set_origin(now_s, ap.system_id)
        rates = self.config.rates
        if self._ask_streams:
            self._ask_streams, self._asked_s, self._fallback_sent = False, now_s, False
            self.counters["stream_requests"] += 1
            gnss_instance = self.config.translate.gnss_instance
            for msg in interval_requests(ap.system_id, ap.component_id, rates, gnss_instance):
                self.conn.send(msg)
            return
        imu_since_ask = self._last_imu_s >= self._asked_s
        if not imu_since_ask and not self._fallback_sent and now_s - self._asked_s > rates.fallback_after_s:
            self._fallback_sent = True
            self.counters["stream_fallback_requests"] += 1
            for req in data_stream_requests(ap.system_id, ap.component_id, rates):
                self.conn.send(req)
        elif now_s - self._asked_s > rates.silence_s and not (now_s - self._last_imu_s <= rates.silence_s):
            self._ask_streams = True  # still (or again) no IMU: ask again

    def _check_origin(self, kind: str, lla: tuple[float, float, float]) -> None:
        """Local-position feeds are about our frame's origin: say so once if the EKF's is elsewhere."""
        local = self.config.feed in ("vision", "odometry")
        if kind != "GPS_GLOBAL_ORIGIN" or not local or self.frame is None:
            return
        offset_m = float(np.linalg.norm(self.frame.to_ned_m(*lla)))
        if offset_m > 1.0 and not self.counters["origin_mismatch"]:
            self.errors.append(f"the autopilot's EKF origin is {offset_m:.1f} m from our frame's origin: "
                               f"its local position is offset by that much")
        self.counters["origin_mismatch"] += offset_m > 1.0

    def _set_origin(self, now_s: float, target_system: int) -> None:
        """Local-position feeds: give an autopilot without an EKF origin ours (1 Hz until it reports one)."""
        frame = self.frame or self.config.home
        if (self.config.feed not in ("vision", "odometry") or frame is None or now_s < self._next_origin_s
                or "GPS_GLOBAL_ORIGIN" in self.origins):
            return
        self._next_origin_s = now_s + 1.0
        self.counters["set_gps_global_origin_sent"] += 1
        self.conn.send(mavlink.MAVLink_set_gps_global_origin_message(
            target_system, round(frame.home_lat_deg * 1e7), round(frame.home_lon_deg * 1e7),
            round(frame.home_alt_m * 1e3), 0))

    # -- results ------------------------------------------------------------------------------
    def nav_counters(self) -> Counter[str]:
        total = Counter(self.past_nav_counters)
        if self.nav is not None:
            total.update(self.nav.counters())
        return total

    def summary(self, wall_s: float) -> dict[str, Any]:
        self.series.trim()
        c = self.config
        nav = self.nav_counters()
        rejected = Counter({k: v for k, v in nav.items() if "rejected" in k and v})
        rejected.update({k: v for k, v in self.translator.counters.items() if v})
        rejected.update({f"autopilot_{k}": v for k, v in self.discovery.counters.items() if v})
        rejected.update({k: v for k, v in self.counters.items()
                         if v and k.startswith(("rejected_", "handler_error_"))})
        if self.counters["samples_before_first_fix"]:
            rejected["before_first_fix"] = self.counters["samples_before_first_fix"]
        if self.conn.counters["bad_frames"]:
            rejected["bad_frames"] = self.conn.counters["bad_frames"]
        ap = self.discovery.autopilot
        beta = np.asarray(self.series.beta, dtype=float)
        p = np.asarray(self.series.p_ned_m, dtype=float).reshape(-1, 3)
        horiz = np.hypot(p[:, 0], p[:, 1])
        return {
            "master": c.master, "method": c.method, "feed": c.feed, "wall_s": wall_s,
            "cpu_s": time.process_time(),
            "autopilot": ap.as_dict() if ap is not None else None,
            "home": None if self.frame is None else {
                "lat_deg": self.frame.home_lat_deg, "lon_deg": self.frame.home_lon_deg,
                "alt_m": self.frame.home_alt_m, "source": self.home_source},
            "autopilot_origins": {k: dict(zip(("lat_deg", "lon_deg", "alt_m"), v, strict=True))
                                  for k, v in self.origins.items()},
            "samples": {"used": {"imu": nav["imu_used"], "attitude": nav["attitude_used"],
                                 "gnss": nav["gnss_fused"]},
                        "rejected": dict(sorted(rejected.items())),
                        "received": dict(sorted(self.received.items()))},
            "estimator_counters": dict(sorted(nav.items())),
            "beta": compare.distribution(beta) | {
                "min": float(beta.min()) if beta.size else None,
                "final": float(beta[-1]) if beta.size else None},
            "estimate": {"count": int(p.shape[0]),
                         "max_horizontal_from_home_m": float(horiz.max()) if p.size else None,
                         "final_p_ned_m": [float(v) for v in p[-1]] if p.size else None},
            "errors": {"autopilot_estimate": self.autopilot_errors()},
            "streams": {"requests": self.counters["stream_requests"],
                        "fallback_requests": self.counters["stream_fallback_requests"],
                        "acks": dict(sorted(self.acks.items()))},
            "timesync": self.timesync.as_dict(),
            "node": dict(sorted(self.counters.items())),
            "link": dict(self.conn.counters),
            "gnss_delay": {"ms": self.translator.gnss_delay_us / 1000.0,
                           "source": self.translator.gnss_delay_source},
            "problems": self.errors,
        }

    def autopilot_errors(self) -> dict[str, Any] | None:
        """Ours vs GLOBAL_POSITION_INT (preferred) or LOCAL_POSITION_NED, origins aligned."""
        s = self.series
        if self.frame is None or len(s.t_us) < 2:
            return None
        t = np.asarray(s.t_us, dtype=np.int64)
        p = np.asarray(s.p_ned_m, dtype=float)
        frame = self.frame
        home = {"lat_deg": frame.home_lat_deg, "lon_deg": frame.home_lon_deg, "alt_m": frame.home_alt_m}
        if s.global_t_us:
            lla = np.asarray(s.global_lla, dtype=float)
            ref = frame.to_ned_m(lla[:, 0], lla[:, 1], lla[:, 2]).T
            result = compare.compare(t, p, np.asarray(s.global_t_us, dtype=np.int64), ref,
                                     self.config.max_gap_us)
            alignment: dict[str, Any] = {
                "reference": "GLOBAL_POSITION_INT", "our_home": home,
                "method": "geodetic: the autopilot's lat/lon/alt (AMSL) converted into our local NED "
                          "frame; nothing fitted"}
        elif s.local_t_us:
            local = np.asarray(s.local_ned_m, dtype=float)
            origin = self.origins.get("GPS_GLOBAL_ORIGIN")
            if origin is not None:
                offset = frame.to_ned_m(*origin)
                result = compare.compare(t, p, np.asarray(s.local_t_us, dtype=np.int64), local + offset,
                                         self.config.max_gap_us)
                alignment = {"reference": "LOCAL_POSITION_NED", "method": "the autopilot's EKF origin "
                             "(GPS_GLOBAL_ORIGIN) placed in our frame", "origin_in_our_frame_ned_m":
                             [float(v) for v in offset], "our_home": home}
            else:
                result = compare.compare(t, p, np.asarray(s.local_t_us, dtype=np.int64), local,
                                         self.config.max_gap_us, fit_translation=True)
                alignment = {"reference": "LOCAL_POSITION_NED", "method": "no origin sent: translation "
                             "fitted (median difference removed), so only the spread is measured",
                             "our_home": home}
        else:
            return None
        alignment["time"] = "autopilot boot time (time_boot_ms); ours interpolated at its stamps"
        return result | {"alignment": alignment}


def _plausible(lat_deg: float, lon_deg: float, alt_m: float) -> bool:
    """A position on (or near) the Earth: the only kind used as a frame origin or a reference."""
    return abs(lat_deg) <= 90 and abs(lon_deg) <= 180 and -1_000 <= alt_m <= 20_000


def _known_satellites(fix: GnssFix | None) -> int:
    """The raw fix's satellite count, -1 when unknown (no fix, or 255 = unknown in MAVLink)."""
    return fix.satellites_visible if fix is not None and fix.satellites_visible < 255 else -1


def _enum(name: str, value: int) -> str:
    entry = mavlink.enums.get(name, {}).get(value)
    return entry.name if entry is not None else str(value)


# -- process ------------------------------------------------------------------------------------


def config_from_args(args: argparse.Namespace) -> CompanionConfig:
    if args.out is None:
        raise UserError("--out DIR is required with --master")
    delay = args.gps_delay_ms
    if delay is not None and not (math.isfinite(delay) and 0 <= delay <= 1000):
        raise UserError(f"--gps-delay-ms {delay}: must be within 0..1000")
    return CompanionConfig(
        master=args.master, out_dir=args.out, method=args.method, feed=args.feed,
        home=parse_home(args.home) if args.home else None, duration_s=args.duration_s,
        component_id=args.component_id, discovery_timeout_s=args.discovery_timeout_s,
        translate=TranslateConfig(gnss_instance=args.gnss_instance,
                                  gnss_delay_us=None if delay is None else round(delay * 1000)))


def run(config: CompanionConfig, telemetry: TelemetryPublisher | None = None) -> dict[str, Any]:
    """Run until ``duration_s`` (or Ctrl-C/SIGTERM); write run.tlog and summary.json; the summary."""
    from companion.runtime import write_json

    config.out_dir.mkdir(parents=True, exist_ok=True)
    conn = open_connection(config.master, 1, config.component_id, config.out_dir / "run.tlog")
    node = AutopilotCompanion(config, conn, telemetry)
    start = time.monotonic()
    try:
        serve(node, start)
    finally:
        summary = node.summary(time.monotonic() - start)
        write_json(config.out_dir / "summary.json", summary)
        conn.close()
        if conn.tlog is not None:
            conn.tlog.close()
    return summary


def serve(node: AutopilotCompanion, start_s: float) -> None:
    c = node.config
    while True:
        now = time.monotonic()
        if c.duration_s is not None and now - start_s >= c.duration_s:
            return
        if node.discovery.autopilot is None and now - start_s > c.discovery_timeout_s:
            node.errors.append("no autopilot HEARTBEAT")
            raise UserError(f"--master {c.master}: no autopilot HEARTBEAT within {c.discovery_timeout_s:g} s")
        node.tick(now)
        for msg in node.conn.recv(timeout_s=0.02):
            node.handle(msg, time.monotonic())
