"""Raw GNSS into ``beliefnav replay --coupling tight``: readers that yield raw epochs (``RawGnss``)
instead of fixes, and the tightly coupled navigator factory.

* ``SmartLocRawSource``: the smartLoc drive as raw epochs (pre-corrected pseudoranges with satellite
  positions) and its wheel odometry (speed, yaw rate; the data set's yaw rate is counter-clockwise,
  so its negative is the NED heading rate), a level attitude and a zero-acceleration input at 50 Hz
  (no inertial data: the filter runs its constant-velocity model), the truth as reference;
* ``LogWithRawGnss``: a flight log whose fixes are dropped (counted) and whose IMU samples carry the
  RINEX epochs, inserted at their receiver times mapped to boot time (``BootTimeMap``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from companion.domain.geodesy import LocalNedFrame
from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
from companion.errors import UserError
from companion.gnss.geometry import ecef_to_geodetic
from companion.gnss.observations import GnssEpoch
from companion.gnss.spp import SppConfig, solve_position
from companion.mission import Mission
from companion.tight import Odometry, RawGnss, TightConfig, TightNavigator
from gcs_tools.gnss.replay import GRAVITY_M_S2, SMARTLOC_IMU_HZ, LogWithGnss, smartloc_boot_us
from gcs_tools.replay.events import TRUTH, Event, LogReader, ReaderStats, Reference, ReferenceInfo

RawEvent = Event | RawGnss | Odometry  # what these readers yield
ODOMETRY_SOURCES = {
    "odom3": "smartLoc odom3 (speed, yaw rate)",
    "imu": "the imu rows' yaw rate about up (no speed: the vehicle does not slide sideways)",
}


def anchor_of(epochs: Sequence[GnssEpoch], klobuchar: Any = None) -> LocalNedFrame:
    """The local frame at the first epoch with a single-point solution."""
    for ep in epochs:
        sol = solve_position(ep, SppConfig(), klobuchar=klobuchar)
        if sol.ok:
            lat, lon, h = (float(v) for v in ecef_to_geodetic(sol.p_ecef_m))
            return LocalNedFrame(float(np.degrees(lat)), float(np.degrees(lon)), h)
    raise UserError("no epoch has a single-point solution: no frame to start from")


@dataclass
class SmartLocRawSource:
    """smartLoc as raw epochs + odometry (see the module doc)."""

    epochs: list[GnssEpoch]
    odometry: np.ndarray  # (m, 3): t_s, speed m/s, yaw rate rad/s (counter-clockwise)
    truth_t_s: np.ndarray
    truth_ecef_m: np.ndarray
    use_odometry: bool = True
    truth_source: str = "smartLoc point3"  # what the truth rows are (gcs_tools.gnss.truth)
    odometry_source: str = "odom3"  # SmartLocInput.odometry_source: "odom3", "imu" (a yaw rate, no speed)
    format: str = "smartloc"
    anchor: LocalNedFrame = field(init=False)

    def __post_init__(self) -> None:
        self.t0_s = float(self.epochs[0].t_gps_s)
        self.stats = ReaderStats()
        self.sources: dict[str, str | None] = {
            "imu": "none (zero acceleration, level: the constant-velocity model)",
            "attitude": "none (level)",
            "gnss": "smartLoc pseudoranges (raw epochs)",
            "odometry": (ODOMETRY_SOURCES.get(self.odometry_source)
                         if self.use_odometry and len(self.odometry) else None),
        }
        note = "estimated position vs the smartLoc truth (ECEF -> geodetic)"
        self.references = {TRUTH: ReferenceInfo(self.truth_source, "geodetic", note)}
        self.anchor = anchor_of(self.epochs)

    def boot_us(self, t_s: float) -> int:
        return int(smartloc_boot_us(t_s, self.t0_s))

    def first_fix(self) -> GnssFix | None:
        return None

    def describe_empty(self) -> str:
        return "no epoch in the smartLoc input"

    def __iter__(self) -> Iterator[RawEvent]:
        lat, lon, h = ecef_to_geodetic(self.truth_ecef_m)
        t_ref = [self.boot_us(float(t)) for t in self.truth_t_s]
        t_ep = [self.boot_us(e.t_gps_s) for e in self.epochs]
        odo = self.odometry if self.use_odometry else np.zeros((0, 3))
        t_odo = [self.boot_us(float(t)) for t in odo[:, 0]]
        t_end = max(t_ep[-1], t_ref[-1]) + 1_000_000
        step = int(1e6 / SMARTLOC_IMU_HZ)
        q, acc, gyro = np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.0, -GRAVITY_M_S2]), np.zeros(3)
        ri = ei = oi = 0
        for t in range(0, t_end, step):
            while ri < len(t_ref) and t_ref[ri] <= t:
                yield Reference(TRUTH, t_ref[ri], float(np.degrees(lat[ri])), float(np.degrees(lon[ri])),
                                float(h[ri]), self.truth_source)
                ri += 1
            self.stats.decoded["imu"] += 1
            self.stats.records += 1
            yield AttitudeSample(t, q)
            yield ImuSample(t, acc, gyro)
            while oi < len(t_odo) and t_odo[oi] <= t:
                self.stats.decoded["odometry"] += 1
                yield Odometry(t_odo[oi], float(odo[oi, 1]), -float(odo[oi, 2]))
                oi += 1
            while ei < len(t_ep) and t_ep[ei] <= t:
                self.stats.decoded["gnss"] += 1
                yield RawGnss(t_ep[ei], self.epochs[ei])
                ei += 1


def smartloc_raw_source(input_path: Path, truth_path: Path | None, use_odometry: bool = True
                        ) -> SmartLocRawSource:
    from gcs_tools.gnss import smartloc

    data, truth = smartloc.read_drive(input_path, truth_path)
    src = SmartLocRawSource(data.epochs, data.odometry, truth.t_s, truth.p_ecef_m, use_odometry,
                            smartloc.truth_label(truth), data.odometry_source)
    src.stats.rejected.update(smartloc.rows_rejected(data.rejected))
    src.stats.rejected.update(smartloc.rows_rejected(truth.rejected, "truth_row"))
    return src


class LogWithRawGnss(LogWithGnss[RawGnss]):
    """A log reader whose fixes are replaced by raw epochs (stamped on boot time), in ``anchor``'s frame;
    each is pushed at its time, or at ``arrival_us(raw)`` when given (a receiver's latency: the filter
    fuses it out of sequence)."""

    def __init__(self, inner: LogReader, raws: Sequence[RawGnss], anchor: LocalNedFrame, source: str,
                 arrival_us: Callable[[RawGnss], int] | None = None) -> None:
        super().__init__(inner, raws, arrival_us or (lambda r: r.t_us), source, "epoch")
        self.anchor = anchor


def rinex_raw_log_reader(log_path: Path, obs: Path, navs: Sequence[Path], gps_delay_ms: float | None = None
                         ) -> tuple[LogWithRawGnss, Any, dict[str, object]]:
    """(the log's reader with RINEX epochs in place of its fixes, the ephemeris store, a summary note)."""
    from gcs_tools.gnss.sources import rinex_input
    from gcs_tools.gnss.timebase import log_time_map
    from gcs_tools.replay.logs import open_log

    data = rinex_input(obs, navs)
    time_map = log_time_map(log_path)
    raws = [RawGnss(time_map.boot_us(e.t_gps_s), e) for e in data.epochs]
    if not raws:
        raise UserError(f"{obs}: no observation epoch")
    store = data.store  # the epochs already carry their satellite states (rinex_input)
    anchor = anchor_of(data.epochs[:50], data.klobuchar)
    reader = LogWithRawGnss(open_log(log_path, gps_delay_ms), raws, anchor, f"RINEX {obs.name} (raw epochs)")
    note: dict[str, object] = {"rinex_obs": str(obs), "rinex_nav": [str(p) for p in navs],
                               "epochs": len(raws), "rejected": dict(data.rejected),
                               "time_join": {"pairs_used": time_map.pairs_used,
                                             "residual_rms_us": time_map.residual_rms_us}}
    return reader, store, note


def ubx_raw_log_reader(log_path: Path, ubx_path: Path, gps_delay_ms: float | None = None
                       ) -> tuple[LogWithRawGnss, Any, dict[str, object]]:
    """(the log's reader with a UBX log's RXM-RAWX epochs in place of its fixes, the ephemeris store, a
    summary note).

    Our simulator's receiver (a ``receiver.json`` beside the UBX log: a ``beliefnav sitl --scenario
    canyon`` run or a canyon flight beside an autopilot): its GPS time of boot joins the two clocks and
    its broadcast ephemerides (every system it tracks) place the satellites, as in the flight. Any other
    receiver: the log's SYSTEM_TIME / GPS time (``log_time_map``) and the ephemerides the UBX log
    carries (RXM-SFRBX: GPS and GLONASS)."""
    import json

    from companion.gnss.ephemeris import attach_broadcast
    from companion.gnss.timescale import BootTimeMap
    from gcs_tools.gnss.timebase import log_time_map
    from gcs_tools.gnss.ubx_source import open_stream, read_ubx_file, ubx_items
    from gcs_tools.replay.logs import open_log

    if not ubx_path.is_file():
        raise UserError(f"--ubx {ubx_path}: no such file")
    info_path = ubx_path.with_name("receiver.json")
    note: dict[str, object] = {"ubx": str(ubx_path)}
    if info_path.is_file():
        from simvehicle.ubx_server import store_from_info

        try:
            info = json.loads(info_path.read_text(encoding="utf-8"))
            t0_gps_s = float(info["t0_gps_s"])
            store = store_from_info(info)
        except (ValueError, KeyError, TypeError) as exc:
            raise UserError(f"{info_path}: not a simulated receiver's description ({exc})") from None
        with open_stream(str(ubx_path)) as f:
            epochs = [e for e in ubx_items(f) if isinstance(e, GnssEpoch)]
        if not epochs:
            raise UserError(f"{ubx_path}: no RXM-RAWX epochs")
        time_map = BootTimeMap.from_gps_pairs(np.array([t0_gps_s]), np.array([0.0]))
        note["time_join"] = {"from": f"{info_path.name} t0_gps_s (GPS time = t0_gps_s + boot time)",
                             "t0_gps_s": t0_gps_s}
        placed = [attach_broadcast(e, store)[0] for e in epochs[:50]]
        anchor = anchor_of([e for e in placed if e.n], store.klobuchar)
    else:
        data = read_ubx_file(ubx_path)
        epochs, store = data.epochs, data.store
        time_map = log_time_map(log_path)
        note["time_join"] = {"pairs_used": time_map.pairs_used, "residual_rms_us": time_map.residual_rms_us}
        note["rejected"] = dict(data.rejected)
        anchor = anchor_of(epochs[:50], data.klobuchar)
    raws = [RawGnss(time_map.boot_us(e.t_gps_s), e) for e in epochs]
    note["epochs"] = len(raws)
    reader = LogWithRawGnss(open_log(log_path, gps_delay_ms), raws, anchor,
                            f"UBX {ubx_path.name} (raw epochs)")
    return reader, store, note


def tight_factory(config: TightConfig, ephemerides: Any = None, mission: Mission | None = None) -> Any:
    """``replay(navigator=…)``: a TightNavigator per segment, in the replay's frame, assembled by
    ``companion.wiring.tight_navigator_for``: with ``mission`` (the log was flown in it) its map's line of
    sight is the per-satellite belief's prior; None: no map."""
    from companion.wiring import tight_navigator_for

    def make(method: str, frame: LocalNedFrame) -> TightNavigator:
        return tight_navigator_for(mission, method, config=config, frame=frame, ephemerides=ephemerides)

    return make
