"""The companion beside a real autopilot: ``python -m companion estimator --master URL``
(= ``beliefnav companion``); :class:`AutopilotCompanion` is everything but the socket loop
(:mod:`.service` runs it).

Order of events: open the connection (nothing is sent before discovery); the autopilot is
elected from the HEARTBEATs the link carries (:mod:`.discovery`); from then on we send our
HEARTBEAT (1 Hz, as MAV_TYPE_ONBOARD_CONTROLLER with the autopilot's system id and our
component id), TIMESYNC requests (1 Hz) and answers, ask for the streams and read the receiver
delay parameter. The local frame is fixed once the fixes agree (:mod:`.frame`); the Navigator
starts there. Samples (one boot-time base, :mod:`.translate`) go to the Navigator in arrival
order; the estimate is compared online with the autopilot's own (:mod:`.compare`, 25 Hz of our
series, bounded memory) and fed back (``--feed``) on the estimate's clock. With
``vision``/``odometry`` our positions are local NED about our frame's origin, which must be the
autopilot's EKF origin: while the autopilot reports no GPS_GLOBAL_ORIGIN (no GPS of its own), we
set it to our frame's origin with SET_GPS_GLOBAL_ORIGIN once a second (``--home`` fixes that
frame from the start).

One clock rule (:mod:`companion.domain.clock_guard`) on the autopilot's boot time: every stamped
message of the autopilot is checked against the time base its stream has shown; a lone stamp
far off is refused and counted (``rejected_clock_<type>``), never adopted; a reboot (the boot
time going back) is believed only when a run of agreeing stamps says so for a while: then a
fresh Navigator starts in the same frame and the streams are asked for again. Over UDP every
frame has the kernel's arrival time, so the forward edge follows the arrivals
(:data:`BOOT_CLOCK_DATAGRAM`: a burst of forged stamps gains 0.2 s at most); a byte stream
(TCP, serial) has no per-frame arrival time once we lag behind, so its forward edge is a fixed
1 s (:data:`BOOT_CLOCK_STREAM`). GNSS validity times must lie near that base
(:data:`GNSS_WINDOW`). A PARAM_VALUE is adopted only as the answer to our own request.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from companion.autopilot import feeds
from companion.autopilot.compare import LiveComparison
from companion.autopilot.connection import MavConnection, PeerPolicy
from companion.autopilot.discovery import Discovery, DiscoveryConfig, enum_name
from companion.autopilot.frame import FrameChooser, FrameConfig, plausible
from companion.autopilot.options import DEFAULT_COMPONENT_ID, FEEDS
from companion.autopilot.status import AutopilotStatus
from companion.autopilot.streams import StreamRates, data_stream_requests, interval_requests
from companion.autopilot.timesync import Timesync, TimesyncConfig
from companion.autopilot.translate import TranslateConfig, Translator, boot_stamp_us
from companion.domain.clock_guard import ClockWindow, StreamClock, Verdict, within
from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import GnssFix, ImuSample, NavEstimate
from companion.errors import UserError
from companion.estimator import DEFAULT_METHOD, EstimatorConfig, Navigator, check_method
from companion.estimator.freespace import FreeSpaceConfig, constrain
from companion.estimator.methods import Clearance
from companion.gnss.ephemeris import EphemerisStore, GlonassEphemeris, KeplerEphemeris
from companion.gnss.observations import GnssEpoch
from companion.gnss.timescale import gps_to_unix_s
from companion.mavlink import codec
from companion.mission import Mission
from companion.telemetry.pubsub import EstimatorTelemetry, TelemetryPublisher
from companion.tight import RawGnss, TightConfig, TightNavigator, check_weighting
from companion.wiring import mission_clearance, navigator_for, tight_navigator_for

ARDUPILOT = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
EPOCH_STRIDE_US = 10**13  # series time key = epoch (reboots) * this + boot µs: monotonic across reboots
REASK_MIN_S = 2.0  # a reboot seen this soon after asking for the streams does not ask again
# The autopilot's boot time, over every stamped message (arrivals: our monotonic clock). Stamps
# lag the newest by up to 0.18 s and lead by 0.02 s (measured on PX4 SITL x10): 1 s back; ahead,
# over UDP 0.2 s beyond an envelope growing 20x the kernel's arrival times (a SITL up to x20),
# over a byte stream 1 s; a jump needs 5 agreeing stamps over 0.25 s of arrivals (a reboot
# keeps streaming on its new base; a forged burst arrives at once)
BOOT_CLOCK_DATAGRAM = ClockWindow(max_back_us=1_000_000, max_forward_us=200_000, consensus_samples=5,
                                  consensus_step_us=1_000_000, consensus_back_us=1_000_000, max_rate=20.0,
                                  consensus_span_us=250_000)
BOOT_CLOCK_STREAM = replace(BOOT_CLOCK_DATAGRAM, max_forward_us=1_000_000, max_rate=0.0)
GNSS_WINDOW = ClockWindow(max_back_us=5_000_000, max_forward_us=500_000)  # a fix's validity vs boot time
PARAM_RETRY_S = 3.0  # the delay parameter is asked again after this without an answer ...
PARAM_TRIES = 3  # ... this many times in all
NOT_REJECTIONS = ("imu_other_source", "attitude_other_source", "gnss_repeated", "system_time_clock_set")


@dataclass(frozen=True, slots=True)
class CompanionConfig:
    master: str  # connection string (companion.autopilot.connection)
    out_dir: Any  # pathlib.Path
    method: str = DEFAULT_METHOD
    feed: str = "none"  # one of FEEDS
    home: LocalNedFrame | None = None  # None: GPS_GLOBAL_ORIGIN, else HOME_POSITION, else the fixes
    duration_s: float | None = None  # wall seconds to run; None: until interrupted
    component_id: int = DEFAULT_COMPONENT_ID
    discovery_timeout_s: float = 60.0  # wall seconds without an autopilot HEARTBEAT = error
    signing_key: bytes | None = None  # MAVLink 2 signing on the link (both ways)
    boot_clock: ClockWindow | None = None  # None: BOOT_CLOCK_DATAGRAM / _STREAM by the link's kind
    heartbeat_period_s: float = 1.0  # our HEARTBEAT (wall clock)
    summary_period_s: float = 1.0  # summary.json rewritten this often (wall clock)
    series_period_us: int = 40_000  # our estimate compared at 25 Hz (boot time)
    max_gap_us: int = 200_000  # no comparison across a longer hole in our series
    rates: StreamRates = field(default_factory=StreamRates)
    translate: TranslateConfig = field(default_factory=TranslateConfig)
    feeds: feeds.FeedConfig = field(default_factory=feeds.FeedConfig)
    discovery: DiscoveryConfig = field(default_factory=DiscoveryConfig)
    frame: FrameConfig = field(default_factory=FrameConfig)
    peers: PeerPolicy = field(default_factory=PeerPolicy)
    timesync: TimesyncConfig = field(default_factory=TimesyncConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    # "tight": the receiver's raw epochs (``ubx``: serial:DEV:BAUD or tcp:HOST:PORT, u-blox UBX) into the
    # tightly coupled filter (companion.tight) instead of the autopilot's fixes; ``method`` names its row
    coupling: str = "loose"
    ubx: str | None = None
    tight: TightConfig = field(default_factory=TightConfig)
    # the mission flown (``--mission``): its buildings are the navigator's map (the tight filter's
    # line-of-sight prior, the map methods), moved into our frame; None: no map
    mission: Mission | None = None
    # with a mission: an estimate inside a building fed at its mean outside them (``companion.estimator.
    # freespace``, ``--free-space``); None: off (the default)
    free_space: FreeSpaceConfig | None = None
    # --coupling tight: the autopilot's SYSTEM_TIME lags GPS time by this (µs); None: the receiver delay
    # in force (``AutopilotCompanion.clock_lag_us``)
    clock_lag_us: int | None = None

    def __post_init__(self) -> None:
        if self.coupling not in ("loose", "tight"):
            raise UserError(f"--coupling {self.coupling!r}: choose from loose, tight")
        (check_weighting if self.coupling == "tight" else check_method)(self.method)
        if self.feed not in FEEDS:
            raise UserError(f"--feed {self.feed!r}: choose from {', '.join(FEEDS)}")
        if not 1 <= self.component_id <= 255:
            raise UserError(f"--component-id {self.component_id}: must be 1..255")
        if self.duration_s is not None and not self.duration_s > 0:
            raise UserError(f"--duration-s {self.duration_s}: must be positive")
        if not (math.isfinite(self.discovery_timeout_s) and self.discovery_timeout_s > 0):
            raise UserError(f"--discovery-timeout-s {self.discovery_timeout_s}: must be a positive number")
        lost = self.discovery.lost_timeout_s
        if not (math.isfinite(lost) and lost > self.discovery.heartbeat_timeout_s):
            raise UserError(f"--lost-timeout-s {lost}: must be a number above "
                            f"{self.discovery.heartbeat_timeout_s:g} s (a HEARTBEAT gap)")


class AutopilotCompanion:
    """Everything but the socket loop: handle(msg) and tick(now) (testable without a network)."""

    def __init__(self, config: CompanionConfig, conn: MavConnection,
                 telemetry: TelemetryPublisher | None = None) -> None:
        self.config = config
        self.conn = conn
        self.discovery = Discovery(config.discovery)
        self.translator = Translator(config.translate)
        self.timesync = Timesync(config.timesync)
        self.frames = FrameChooser(config.frame, config.home)
        self.exact_arrivals = bool(getattr(conn, "exact_arrivals", False))
        window = config.boot_clock or (BOOT_CLOCK_DATAGRAM if self.exact_arrivals else BOOT_CLOCK_STREAM)
        self.clock = StreamClock(window)
        self.telemetry = telemetry or TelemetryPublisher.disabled()
        self._topics = EstimatorTelemetry(self.telemetry)
        self.status = AutopilotStatus(self.telemetry)  # status (mode, armed) and gnss for the ground tools
        self.nav: Navigator | TightNavigator | None = None
        self._free_space: Clearance | None = None  # the map's clearance in our frame (--mission)
        self._ephemerides: dict[tuple[int, int], KeplerEphemeris] = {}  # (PRN, IODE) -> from the receiver
        self._glonass: dict[tuple[int, float], GlonassEphemeris] = {}  # (slot, t_b) -> from the receiver
        self._klobuchar: Any = None
        self.counters: Counter[str] = Counter()
        self.received: Counter[str] = Counter()
        self.acks: Counter[str] = Counter()
        self.past_nav_counters: Counter[str] = Counter()
        self.comparison = LiveComparison(config.max_gap_us)
        self.epoch = 0
        self.errors: list[str] = []  # summary.problems: what went wrong, each kind once
        self._alarms_seen = 0
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
        self._param_asked_s = math.nan
        self._param_tries = 0
        self._next_origin_s = 0.0

    @property
    def frame(self) -> LocalNedFrame | None:
        return self.frames.frame

    def problem(self, key: str, text: str) -> None:
        """Report ``text`` once per ``key`` (summary.problems and stderr)."""
        if self.counters[f"problem_{key}"] == 0:
            print(f"companion: {text}", file=sys.stderr)
            self.errors.append(text)
        self.counters[f"problem_{key}"] += 1

    # -- incoming -----------------------------------------------------------------------------
    def handle(self, msg: Any, now_s: float) -> None:
        """Handle one message; whatever it holds, count it and never raise."""
        try:
            self._handle(msg, now_s)
        except Exception as exc:  # noqa: BLE001 - a frame must never end the process
            self.problem(f"handler_{msg.get_type()}_{type(exc).__name__}",
                         f"{msg.get_type()}: {type(exc).__name__}: {exc}")
            self.counters[f"handler_error_{msg.get_type()}_{type(exc).__name__}"] += 1

    def _handle(self, msg: Any, now_s: float) -> None:
        d = self.discovery
        was_known = d.autopilot is not None
        ours = d.accept(msg, now_s)
        if not was_known and d.autopilot is not None:
            self._discovered(now_s)
        while self._alarms_seen < len(d.alarms):
            self.problem(f"alarm_{self._alarms_seen}", d.alarms[self._alarms_seen])
            self._alarms_seen += 1
        if not ours:
            return
        self.conn.note_peer(msg, now_s)
        kind = msg.get_type()
        self.received[kind] += 1
        stamp = boot_stamp_us(msg)
        if stamp is not None:
            arrival = self.conn.arrival_us(msg) if self.exact_arrivals else None
            if not self._boot_time_ok(kind, stamp, round(now_s * 1e6) if arrival is None else arrival, now_s):
                return
        if kind == "HEARTBEAT":
            self.status.heartbeat(msg, self.clock.base_us or 0, now_s, self.frame)
        elif kind == "TIMESYNC":
            answer = self.timesync.handle(msg, time.monotonic_ns())
            if answer is not None:
                self.conn.send(answer)
        elif kind == "COMMAND_ACK":
            self.acks[f"{enum_name('MAV_CMD', msg.command)}:{enum_name('MAV_RESULT', msg.result)}"] += 1
        elif kind == "PARAM_VALUE":
            self._param_value(msg)
        elif kind == "SYSTEM_TIME":
            self.translator.system_time(msg)
        elif kind in ("GPS_GLOBAL_ORIGIN", "HOME_POSITION"):  # degE7, mm AMSL
            lla = (msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3)
            if self.frames.origin(kind, lla):
                self._check_origin(kind, lla)
        elif kind == "GLOBAL_POSITION_INT":
            self._reference_global(msg)
        elif kind == "LOCAL_POSITION_NED":
            p = (float(msg.x), float(msg.y), float(msg.z))
            if not all(math.isfinite(v) and abs(v) <= codec.LIMITS.max_home_distance_m for v in p):
                self.counters["rejected_local_position_ned"] += 1
            elif self.nav is not None:
                self.comparison.reference_local(self._key(int(msg.time_boot_ms) * 1000), p)
        else:
            sample = self.translator.sample(msg)
            if kind == self.translator.config.gnss_type:
                fix = sample if isinstance(sample, GnssFix) else None
                self.status.gnss(msg, fix, self.clock.base_us or 0, now_s)
            if sample is not None:
                self._push(sample, now_s)

    def _discovered(self, now_s: float) -> None:
        ap = self.discovery.autopilot
        assert ap is not None
        self.conn.set_source(ap.system_id, self.config.component_id)
        self._ask_streams = True
        self._delay_param = self.translator.delay_parameter(ap.autopilot_type)
        self._next_heartbeat_s = self._next_timesync_s = now_s

    def _boot_time_ok(self, kind: str, stamp_us: int, arrival_us: int, now_s: float) -> bool:
        """The one clock rule on the autopilot's boot time (see the module doc)."""
        before = self.clock.base_us
        verdict = self.clock.check(stamp_us, arrival_us)
        if verdict is Verdict.REJECT:
            self.counters[f"rejected_clock_{kind.lower()}"] += 1
            return False
        if verdict is Verdict.RESET:
            if before is not None and stamp_us < before:
                self._rebooted(now_s)
            else:
                self.counters["autopilot_clock_jumps_forward"] += 1
        return True

    def _param_value(self, msg: Any) -> None:
        """Only the answer to our own request is adopted: once, in range (see .translate)."""
        ap = self.discovery.autopilot
        name = str(msg.param_id)
        asked = self._delay_param is not None and not math.isnan(self._param_asked_s)
        if ap is None or not asked or name != self._delay_param:
            self.counters["param_value_unsolicited"] += 1
            return
        self._param_asked_s = math.nan  # answered: a later one is unsolicited
        value = float(msg.param_value)
        if not self.translator.delay_parameter_value(ap.autopilot_type, name, value):
            self.problem("gnss_delay_range", f"the autopilot's {name} = {value:g} ms is outside its range: "
                         f"{self.translator.gnss_delay_us / 1000:g} ms kept")

    def _reference_global(self, msg: Any) -> None:
        if msg.lat == 0 and msg.lon == 0:  # ArduPilot before its EKF has a position
            self.counters["reference_without_position"] += 1
            return
        lla = (msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1e3)
        if not plausible(*lla):
            self.counters["rejected_global_position_int"] += 1
            return
        if self.frame is None or self.nav is None:
            self.counters["reference_before_estimate"] += 1
            return
        self.comparison.reference_global(self._key(int(msg.time_boot_ms) * 1000), self.frame.to_ned_m(*lla))

    def _key(self, t_us: int) -> int:
        return self.epoch * EPOCH_STRIDE_US + t_us

    def _push(self, sample: Any, now_s: float) -> None:
        if isinstance(sample, GnssFix):
            base = self.clock.base_us
            if base is not None and not within(sample.t_validity_us, base, GNSS_WINDOW):
                self.counters["rejected_clock_gnss"] += 1
                return
            if not self.frames.fix(sample):
                if self.frame is None:
                    self.counters["samples_before_first_fix"] += 1
                return
            if self.nav is None:
                self._start_navigator()
        if self.nav is None:
            self.counters["samples_before_first_fix"] += 1
            return
        self.nav.push(sample)
        if isinstance(sample, ImuSample):
            self._last_imu_s = now_s
            self._after_imu(sample.t_us)

    def _start_navigator(self) -> None:
        # the mission's map, in our frame; our own filter settings (the autopilot's sensors)
        mission = self.config.mission
        if mission is not None and self.config.free_space is not None:
            self._free_space = mission_clearance(mission, self.frame)
        if self.config.coupling == "tight":
            self.nav = tight_navigator_for(mission, self.config.method, config=self.config.tight,
                                           frame=self.frame, ephemerides=self._store())
        else:
            self.nav = navigator_for(mission, self.config.method, config=self.config.estimator,
                                     frame=self.frame)
        self._topics = EstimatorTelemetry(self.telemetry)

    # -- the receiver's raw GNSS (--coupling tight) --------------------------------------------
    def _store(self) -> EphemerisStore | None:
        if not self._ephemerides and not self._glonass:
            return None
        return EphemerisStore(list(self._ephemerides.values()), list(self._glonass.values()), self._klobuchar)

    def raw_items(self, items: list[Any]) -> None:
        """The receiver's decoded items (``RawReceiver.drain()``), in arrival order: ephemerides go to
        the filter, each raw epoch is put on the autopilot's boot clock (its SYSTEM_TIME: the
        epoch's GPS time as Unix time minus the autopilot's Unix − boot offset) and fused. Counted,
        never raised."""
        for item in items:
            try:
                self._raw_item(item)
            except Exception as exc:  # noqa: BLE001 - the receiver's data must never end the process
                self.counters[f"raw_error_{type(exc).__name__}"] += 1

    def _raw_item(self, item: Any) -> None:
        if isinstance(item, KeplerEphemeris | GlonassEphemeris):
            if isinstance(item, KeplerEphemeris):
                self._ephemerides[(item.prn, item.iode)] = item
            else:
                self._glonass[(item.prn, item.toe_gps_s)] = item
            self.counters["raw_ephemerides"] += 1
            if isinstance(self.nav, TightNavigator):
                store = self._store()
                assert store is not None
                self.nav.update_ephemerides(store)
        elif isinstance(item, GnssEpoch):
            offset_us = self.translator.unix_minus_boot_us
            if offset_us is None:
                self.counters["raw_before_system_time"] += 1
            elif not isinstance(self.nav, TightNavigator):
                self.counters["raw_before_first_fix"] += 1
            else:
                t_us = round(gps_to_unix_s(item.t_gps_s) * 1e6) - offset_us - self.clock_lag_us
                base = self.clock.base_us  # the one clock rule, as for the autopilot's fixes
                if base is not None and not within(t_us, base, GNSS_WINDOW):
                    self.counters["rejected_clock_raw"] += 1
                    return
                self.nav.push(RawGnss(t_us, item))
                self.counters["raw_epochs"] += 1
        else:
            self.counters["raw_receiver_fixes"] += 1

    @property
    def clock_lag_us(self) -> int:
        """How far the autopilot's SYSTEM_TIME lags GPS time: ``clock_lag_us`` if given, else the receiver
        delay in force beside ArduPilot (its GPSn_DELAY_MS, or ``--gps-delay-ms``), else 0. ArduPilot sets its
        clock
        from a fix's GPS time when the fix ARRIVES (and keeps it), so its clock lags by that receiver's
        latency, which is what GPSn_DELAY_MS declares (measured beside ArduPilot SITL on the canyon
        receiver, 80 ms latency: 84.0-84.5 ms, constant; the first fix reached it 93 ms after its
        measurement)."""
        lag = self.config.clock_lag_us
        if lag is not None:
            return lag
        ap = self.discovery.autopilot  # PX4's SYSTEM_TIME is its host's clock, not a fix's
        return self.translator.gnss_delay_us if ap is not None and ap.autopilot_type == ARDUPILOT else 0

    def set_klobuchar(self, klobuchar: Any) -> None:
        self._klobuchar = klobuchar

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
            self.comparison.estimate(self._key(est.t_us), est.p_ned_m, float(est.beta))
        if due_feed:
            # on a fixed cadence (next = previous + period), not "period after the IMU sample that
            # was due": at 50 Hz IMU that would add up to 20 ms to every period
            period = self.config.feeds.period_us(self.config.feed)
            nxt = self._next_feed_us + period
            self._next_feed_us = nxt if nxt > t_us else t_us + period
            self._send_feed(est)

    def _send_feed(self, est: NavEstimate) -> None:
        try:  # nothing absurd is sent: not finite, beyond the codec's limits (counted, not raised)
            codec.check_sendable(est)
        except codec.CodecError as exc:
            self.counters[f"unsendable_{exc.reason}"] += 1
            return
        est = self._in_free_space(est)
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
        else:
            assert self.frame is not None
            origin = feeds.local_origin_ned_m(self.frame, self.frames.origins.get("GPS_GLOBAL_ORIGIN"))
            if feed == "vision":
                msg = feeds.vision_position(est, tr.last_attitude.q_ned_frd, self.config.feeds, origin)
            else:
                msg = feeds.odometry(est, tr.last_attitude.q_ned_frd, tr.last_imu.gyro_frd_rad_s,
                                     self.config.feeds, origin)
        if self.conn.send(msg):
            self.counters[f"feed_{msg.get_type().lower()}_sent"] += 1

    def _in_free_space(self, est: NavEstimate) -> NavEstimate:
        """The fed estimate constrained to the map's free space (unchanged without a map or away from
        buildings); counted when moved."""
        if self._free_space is None or self.config.free_space is None:
            return est
        c = constrain(np.asarray(est.p_ned_m)[:2], np.asarray(est.cov_diag)[:2], self._free_space,
                      self.config.free_space)
        if c is None:
            return est
        self.counters["free_space_constrained"] += 1
        p = np.array([c.p_ne_m[0], c.p_ne_m[1], est.p_ned_m[2]])
        cov = np.array(est.cov_diag, dtype=float)
        cov[:2] = c.var_ne_m2
        return replace(est, p_ned_m=p, cov_diag=cov)

    def _rebooted(self, now_s: float) -> None:
        self.counters["autopilot_reboots"] += 1
        if self.nav is not None:
            self.past_nav_counters.update(self.nav.counters())
        self.nav = None
        self.epoch += 1
        self.comparison.restart()
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
        self._ask_parameter(now_s, ap.system_id, ap.component_id)
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

    def _ask_parameter(self, now_s: float, system_id: int, component_id: int) -> None:
        """Read the receiver delay (PARAM_REQUEST_READ), again if unanswered, a few times at most."""
        if self._delay_param is None or self._param_tries >= PARAM_TRIES:
            return
        answered = math.isnan(self._param_asked_s)
        if self._param_tries and (answered or now_s - self._param_asked_s < PARAM_RETRY_S):
            return  # answered, or still waiting
        self._param_tries += 1
        self._param_asked_s = now_s
        self.conn.send(mavlink.MAVLink_param_request_read_message(
            system_id, component_id, self._delay_param.encode(), -1))

    def _check_origin(self, kind: str, lla: tuple[float, float, float]) -> None:
        """Local-position feeds are sent about the EKF's origin (``feeds.local_origin_ned_m``): counted
        while it is more than 1 m from ours horizontally (an origin from the autopilot's own first fix)."""
        local = self.config.feed in ("vision", "odometry")
        if kind != "GPS_GLOBAL_ORIGIN" or not local or self.frame is None:
            return
        offset_m = float(np.linalg.norm(feeds.local_origin_ned_m(self.frame, lla)))
        self.counters["feed_about_autopilot_origin"] += offset_m > 1.0

    def _set_origin(self, now_s: float, target_system: int) -> None:
        """Local-position feeds: give an autopilot without an EKF origin ours (1 Hz until it reports one)."""
        frame = self.frame
        if (self.config.feed not in ("vision", "odometry") or frame is None or now_s < self._next_origin_s
                or "GPS_GLOBAL_ORIGIN" in self.frames.origins):
            return
        self._next_origin_s = now_s + 1.0
        self.counters["set_gps_global_origin_sent"] += 1
        self.conn.send(mavlink.MAVLink_set_gps_global_origin_message(
            target_system, round(frame.home_lat_deg * 1e7), round(frame.home_lon_deg * 1e7),
            round(frame.home_alt_m * 1e3), 0))

    # -- results ------------------------------------------------------------------------------
    def finish(self) -> None:
        """A clean end: the last ``health`` says ``ended`` (nothing before the first estimate)."""
        self._topics.finish(self.nav)

    def nav_counters(self) -> Counter[str]:
        total = Counter(self.past_nav_counters)
        if self.nav is not None:
            total.update(self.nav.counters())
        return total

    def summary(self, wall_s: float) -> dict[str, Any]:
        c = self.config
        nav = self.nav_counters()
        rejected = Counter({k: v for k, v in nav.items() if "rejected" in k and v})
        rejected.update({k: v for k, v in self.translator.counters.items() if v and k not in NOT_REJECTIONS})
        rejected.update({f"autopilot_{k}": v for k, v in self.discovery.counters.items() if v})
        rejected.update({k: v for k, v in (*self.counters.items(), *self.frames.counters.items())
                         if v and k.startswith(("rejected_", "handler_error_", "unsendable_"))})
        if self.counters["samples_before_first_fix"]:
            rejected["before_first_fix"] = self.counters["samples_before_first_fix"]
        if self.counters["param_value_unsolicited"]:
            rejected["param_value_unsolicited"] = self.counters["param_value_unsolicited"]
        ap = self.discovery.autopilot
        cmp_ = self.comparison
        frame = self.frame
        return {
            "master": c.master, "method": c.method, "feed": c.feed, "coupling": c.coupling, "wall_s": wall_s,
            "mission": None if c.mission is None else c.mission.name,
            "cpu_s": time.process_time(),
            "autopilot": ap.as_dict() if ap is not None else None,
            "conflicting_autopilots": sorted(self.discovery.conflicting_systems),
            "home": None if frame is None else {
                "lat_deg": frame.home_lat_deg, "lon_deg": frame.home_lon_deg,
                "alt_m": frame.home_alt_m, "source": self.frames.source},
            "autopilot_origins": {k: dict(zip(("lat_deg", "lon_deg", "alt_m"), v, strict=True))
                                  for k, v in self.frames.origins.items()},
            "samples": {"used": {"imu": nav["imu_used"], "attitude": nav["attitude_used"],
                                 "gnss": nav["gnss_fused"]},
                        "rejected": dict(sorted(rejected.items())),
                        "received": dict(sorted(self.received.items()))},
            "estimator_counters": dict(sorted(nav.items())),
            "beta": cmp_.beta_summary(),
            "estimate": {"count": cmp_.count,
                         "max_horizontal_from_home_m": None if math.isnan(cmp_.max_horizontal_m)
                         else cmp_.max_horizontal_m,
                         "final_p_ned_m": None if cmp_.final_p_ned_m is None else list(cmp_.final_p_ned_m)},
            "errors": {"autopilot_estimate": self.autopilot_errors()},
            "streams": {"requests": self.counters["stream_requests"],
                        "fallback_requests": self.counters["stream_fallback_requests"],
                        "acks": dict(sorted(self.acks.items()))},
            "timesync": self.timesync.as_dict(),
            "clock": {"base_us": self.clock.base_us, "resets": self.clock.resets,
                      "rejected": self.clock.rejected, "system_time_lag_ms": self.clock_lag_us / 1000.0,
                      "system_time_lag_source": "receiver delay" if c.clock_lag_us is None else "option"},
            "node": dict(sorted(self.counters.items())),
            "link": dict(sorted(self.conn.counters.items())),
            "gnss_delay": {"ms": self.translator.gnss_delay_us / 1000.0,
                           "source": self.translator.gnss_delay_source},
            "problems": list(self.errors),
        }

    def autopilot_errors(self) -> dict[str, Any] | None:
        """Ours vs GLOBAL_POSITION_INT (preferred) or LOCAL_POSITION_NED, origins aligned."""
        frame = self.frame
        if frame is None:
            return None
        origin = self.frames.origins.get("GPS_GLOBAL_ORIGIN")
        offset = None if origin is None else frame.to_ned_m(*origin)
        found = self.comparison.errors(offset)
        if found is None:
            return None
        result, how = found
        home = {"lat_deg": frame.home_lat_deg, "lon_deg": frame.home_lon_deg, "alt_m": frame.home_alt_m}
        alignments: dict[str, dict[str, Any]] = {
            "global": {"reference": "GLOBAL_POSITION_INT", "method": "geodetic: the autopilot's lat/lon/alt "
                       "(AMSL) converted into our local NED frame; nothing fitted"},
            "local_origin": {"reference": "LOCAL_POSITION_NED", "method": "the autopilot's EKF origin "
                             "(GPS_GLOBAL_ORIGIN) placed in our frame",
                             "origin_in_our_frame_ned_m": None if offset is None else offset.tolist()},
            "local_fitted": {"reference": "LOCAL_POSITION_NED", "method": "no origin sent: translation "
                             "fitted (median difference removed), so only the spread is measured"},
        }
        alignment = alignments[how] | {
            "our_home": home, "time": "autopilot boot time (time_boot_ms); ours interpolated at its stamps"}
        return result | {"alignment": alignment}


def _known_satellites(fix: GnssFix | None) -> int:
    """The raw fix's satellite count, -1 when unknown (no fix, or 255 = unknown in MAVLink)."""
    return fix.satellites_visible if fix is not None and fix.satellites_visible < 255 else -1
