"""u-blox UBX messages (as parsed by ``pyubx2``) -> raw epochs, the receiver's own fix, ephemerides.

Pure: :class:`UbxDecoder` takes parsed messages (anything with pyubx2's ``identity`` and field
attributes) in arrival order; opening a file, serial port or TCP stream is the caller's
(``companion.receiver.ubx_stream``).

* ``RXM-RAWX`` -> :class:`GnssEpoch` at ``week · 604800 + rcvTow`` (receiver time, GPS scale): one
  signal per system (GPS/QZSS L1 C/A, Galileo E1, BeiDou B1I, GLONASS L1OF), pseudoranges with
  ``prValid``, variance ``(0.01 · 2^prStd)²`` m², pseudorange rate ``−λ · doMes`` (GLONASS λ from
  ``freqId − 7``), C/N0; elevation/azimuth from the latest ``NAV-SAT``.
* ``RXM-SFRBX`` GPS L1 C/A -> :class:`KeplerEphemeris` and Klobuchar (:mod:`companion.gnss.lnav`);
  GLONASS L1OF strings 1-4 -> :class:`GlonassEphemeris` (:mod:`companion.gnss.glonav`, the channel
  from ``freqId``); Galileo I/NAV page pairs (word types 1-5) -> :class:`KeplerEphemeris`
  (:mod:`companion.gnss.inav`, CRC-24Q checked); BeiDou D1 subframes 1-3 -> :class:`KeplerEphemeris`
  (:mod:`companion.gnss.bdsnav`, BCH parity checked; the GEO satellites' D2 subframe 1 pages
  alike); other systems (SBAS, QZSS) counted as ``sfrbx_not_decoded_<system>``.
  Every refusal has a named counter (``<system>_bad_crc``, ``beidou_bad_parity``, ...).
* ``NAV-PVT`` -> :class:`ReceiverPvt` (the receiver's own solution with its accuracies); a solution
  outside the Earth's ranges (latitude, longitude, height, speed, fix type, time of week) is refused
  (``pvt_out_of_range``).

Damaged input is counted, never used and never raised (``feed_all``): a signal's C/N0 beyond
``MAX_CN0_DBHZ`` drops that signal (``rawx_invalid_cn0``); a Doppler not finite or beyond
``MAX_RANGE_RATE_M_S`` leaves its pseudorange rate NaN (``rawx_invalid_doppler``); a message whose
fields cannot be read is ``bad_<identity>``. Epoch times keep order: a repeated time is
``rawx_duplicate_epoch``; an epoch not within ``MAX_EPOCH_STEP_S`` after the last one kept (back in
time, or jumping ahead; for a receiver slower than that, 1.5 of its intervals) is held until the next
epoch tells: if that one follows the last kept, the
held one was a lone damaged time (``rawx_lone_time_back`` / ``rawx_lone_time_ahead``, dropped); if it
follows the held one, the receiver's time really jumped (``rawx_time_jump``) and both are released;
one still held when a file ends is counted ``rawx_unconfirmed_at_end`` (``end_of_stream``).
On a live stream the epochs' arrival times (``feed_all``'s ``arrival_s``) tell more: an epoch after a gap
(a tunnel: the receiver's epochs without a signal decode to none) whose GPS time advanced since the last
one kept as much as the stream's clock did (within ``RESUME_TOLERANCE_S``) continues the receiver's own
clock and is released at once (``rawx_resumed``), not one epoch late; a damaged stamp (a week back or
ahead) or a real jump of the receiver's time disagrees with the stream's clock and is held as above.
A damaged time within ``MAX_EPOCH_STEP_S`` of the truth cannot be told from a real one.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.gnss.bdsnav import BeidouDecoder
from companion.gnss.constants import C_M_S, DFREQ_G1_HZ, FREQ_B1I_HZ, FREQ_G1_HZ, FREQ_L1_HZ
from companion.gnss.ephemeris import GlonassEphemeris, KeplerEphemeris
from companion.gnss.glonav import GlonassDecoder
from companion.gnss.inav import GalileoDecoder
from companion.gnss.lnav import LnavDecoder
from companion.gnss.observations import GnssEpoch, make_epoch
from companion.gnss.systems import SHORT_NAME, System
from companion.gnss.timescale import gps_from_calendar, gps_from_week_tow

# (gnssId, sigId) of the signal taken per system (UBX interface description, "Signal identifiers")
PRIMARY_SIGNALS = {(0, 0), (2, 0), (2, 1), (3, 0), (3, 1), (5, 0), (6, 0)}
KNOWN_SYSTEMS = {int(s) for s in System}
MAX_EPOCH_STEP_S = 2.0  # a 1 Hz receiver missing one epoch; a longer step is held for the next to confirm
# a longer step released at once when the stream's clock elapsed as much (transport and scheduling jitter)
RESUME_TOLERANCE_S = 0.5
MAX_CN0_DBHZ = 80.0  # receivers report 0-60 dB-Hz; beyond is a damaged field (the belief would trust it)
MAX_RANGE_RATE_M_S = 10_000.0  # satellite motion (< 1 km/s) plus a receiver clock drift up to ~30 ppm


def _step_limit_s(step_s: float) -> float:
    """The longest step an epoch may follow the last by without being held: ``MAX_EPOCH_STEP_S``, or 1.5
    receiver intervals for a receiver slower than that (a 30 s logger's epochs are not each a jump)."""
    return max(MAX_EPOCH_STEP_S, 1.5 * step_s)


@dataclass(frozen=True, slots=True)
class ReceiverPvt:
    """The receiver's own navigation solution (NAV-PVT)."""

    t_gps_s: float  # from iTOW and the last RAWX week (NaN before one)
    fix_type: int
    lat_deg: float
    lon_deg: float
    height_ellipsoid_m: float
    height_msl_m: float
    h_acc_m: float
    v_acc_m: float
    v_ned_m_s: tuple[float, float, float]
    s_acc_m_s: float
    num_sv: int
    pdop: float
    t_utc_gps_s: float = math.nan  # the UTC date/time fields as GPS time when valid


UbxItem = GnssEpoch | ReceiverPvt | KeplerEphemeris | GlonassEphemeris


@dataclass
class UbxDecoder:
    counters: Counter[str] = field(default_factory=Counter)
    lnav: LnavDecoder = field(default_factory=LnavDecoder)
    glonav: GlonassDecoder = field(default_factory=GlonassDecoder)
    inav: GalileoDecoder = field(default_factory=GalileoDecoder)
    bdsnav: BeidouDecoder = field(default_factory=BeidouDecoder)
    week: int | None = None  # from the last RAWX
    t_gps_s: float | None = None  # the last RAWX's receiver time (resolves LNAV's 10-bit week)
    _sat: dict[tuple[int, int], tuple[float, float]] = field(default_factory=dict)  # el, az (deg)
    _held: tuple[int, float, GnssEpoch] | None = None  # an epoch out of time order: week, time, epoch
    _step_s: float = 0.0  # between the last two epochs kept: the receiver's interval (a slow one's too)
    _arrival_s: float | None = None  # the stream's clock when the last epoch kept arrived (live streams)

    @property
    def klobuchar(self) -> tuple[np.ndarray, np.ndarray] | None:
        return self.lnav.klobuchar

    def feed_all(self, msg: Any, arrival_s: float | None = None) -> list[UbxItem]:
        """The items one message gives (none, one, or a held epoch and this one); never raises.
        ``arrival_s``: when it arrived on a live stream (a monotonic clock, seconds), None from a file."""
        try:
            if getattr(msg, "identity", "") == "RXM-RAWX":
                return self._rawx(msg, arrival_s)
            item = self.feed(msg)
        except Exception:  # noqa: BLE001 - a field pyubx2 gave that cannot be read: counted, not used
            self.counters[f"bad_{getattr(msg, 'identity', '') or 'message'}"] += 1
            return []
        return [] if item is None else [item]

    def feed(self, msg: Any) -> UbxItem | None:
        """One message's item (the last of ``feed_all``'s: use that on a live stream)."""
        ident = getattr(msg, "identity", "")
        if ident == "RXM-RAWX":
            items = self._rawx(msg)
            return items[-1] if items else None
        if ident == "RXM-SFRBX":
            return self._sfrbx(msg)
        if ident == "NAV-PVT":
            return self._pvt(msg)
        if ident == "NAV-SAT":
            self._navsat(msg)
            return None
        self.counters[f"ignored_{ident or 'unknown'}"] += 1
        return None

    def _rawx(self, m: Any, arrival_s: float | None = None) -> list[UbxItem]:
        tow, week = float(m.rcvTow), int(m.week)
        if not (math.isfinite(tow) and 0.0 <= tow < 604800.0 and week > 0):
            self.counters["rawx_bad_time"] += 1
            return []
        t = gps_from_week_tow(week, tow)
        if t == self.t_gps_s:
            self.counters["rawx_duplicate_epoch"] += 1
            return []
        epoch = self._rawx_epoch(m, t)
        if epoch is None:
            return []
        last, held = self.t_gps_s, self._held
        if last is not None and not 0.0 < t - last <= _step_limit_s(self._step_s):
            if held is not None and 0.0 < t - held[1] <= _step_limit_s(held[1] - last):
                # the time really jumped (or the receiver is slower than one epoch per 2 s: its interval)
                self.counters["rawx_time_jump"] += 1
                self._held = None
                self.counters["rawx_epochs"] += 2
                self.week, self.t_gps_s, self._step_s = week, t, t - held[1]
                self._arrival_s = arrival_s
                return [held[2], epoch]
            self._drop_held()
            if self._resumes(t - last, arrival_s):
                self.counters["rawx_resumed"] += 1  # after a gap, on the receiver's own clock
                self._step_s = self._step_s or t - last  # a gap is no interval (unless none is known)
                return self._keep(week, t, arrival_s, epoch)
            self._held = (week, t, epoch)  # until the next epoch tells whether it was alone
            return []
        self._drop_held()
        self._step_s = t - last if last is not None else 0.0
        return self._keep(week, t, arrival_s, epoch)

    def _resumes(self, step_s: float, arrival_s: float | None) -> bool:
        """Whether an epoch ``step_s`` after the last kept, out of step, continues the receiver's clock:
        the stream's clock (live streams only) elapsed as much since the last kept one arrived."""
        if arrival_s is None or self._arrival_s is None or step_s <= 0.0:
            return False
        return abs(step_s - (arrival_s - self._arrival_s)) <= RESUME_TOLERANCE_S

    def _keep(self, week: int, t: float, arrival_s: float | None, epoch: GnssEpoch) -> list[UbxItem]:
        self.week, self.t_gps_s, self._arrival_s = week, t, arrival_s
        self.counters["rawx_epochs"] += 1
        return [epoch]

    def end_of_stream(self) -> None:
        """The stream ended for good (a file): an epoch still held for confirmation cannot be told from a
        lone damaged time any more: dropped and counted (``rawx_unconfirmed_at_end``), not lost unseen."""
        if self._held is not None:
            self.counters["rawx_unconfirmed_at_end"] += 1
            self._held = None

    def _drop_held(self) -> None:
        if self._held is not None and self.t_gps_s is not None:
            back = self._held[1] < self.t_gps_s
            self.counters["rawx_lone_time_back" if back else "rawx_lone_time_ahead"] += 1
        self._held = None

    def _rawx_epoch(self, m: Any, t: float) -> GnssEpoch | None:
        n = int(m.numMeas)
        sysv, prnv, pr, var, rate, cn0, el, az = [], [], [], [], [], [], [], []
        for i in range(1, n + 1):
            s = f"_{i:02d}"
            gnss, sv, sig = (
                int(getattr(m, "gnssId" + s)),
                int(getattr(m, "svId" + s)),
                int(getattr(m, "sigId" + s, 0)),
            )
            if gnss not in KNOWN_SYSTEMS or gnss == System.SBAS:
                self.counters["rawx_unknown_system"] += 1
                continue
            if (gnss, sig) not in PRIMARY_SIGNALS:
                self.counters["rawx_other_signal"] += 1
                continue
            p = float(getattr(m, "prMes" + s))
            if not int(getattr(m, "prValid" + s, 1)) or not math.isfinite(p) or not 1.0e7 < p < 5.0e7:
                self.counters["rawx_invalid_pseudorange"] += 1
                continue
            system = System(gnss)
            if system == System.GLONASS:
                lam = C_M_S / (FREQ_G1_HZ + (int(getattr(m, "freqId" + s)) - 7) * DFREQ_G1_HZ)
            elif system == System.BEIDOU:
                lam = C_M_S / FREQ_B1I_HZ
            else:
                lam = C_M_S / FREQ_L1_HZ
            c = float(getattr(m, "cno" + s))
            if not 0.0 <= c <= MAX_CN0_DBHZ:
                self.counters["rawx_invalid_cn0"] += 1
                continue
            rr = -lam * float(getattr(m, "doMes" + s))
            if not (math.isfinite(rr) and abs(rr) <= MAX_RANGE_RATE_M_S):
                self.counters["rawx_invalid_doppler"] += 1
                rr = math.nan
            sysv.append(gnss)
            prnv.append(sv)
            pr.append(p)
            var.append((0.01 * 2.0 ** int(getattr(m, "prStd" + s, 0))) ** 2)
            rate.append(rr)
            cn0.append(c)
            e_a = self._sat.get((gnss, sv), (math.nan, math.nan))
            el.append(e_a[0])
            az.append(e_a[1])
        if not sysv:
            self.counters["rawx_empty"] += 1
            return None
        return make_epoch(
            t,
            sysv,
            prnv,
            pr,
            pseudorange_var_m2=var,
            pseudorange_rate_m_s=rate,
            cn0_dbhz=cn0,
            elevation_deg=el,
            azimuth_deg=az,
        )

    def _sfrbx(self, m: Any) -> KeplerEphemeris | GlonassEphemeris | None:
        gnss = int(m.gnssId)
        if gnss == System.GLONASS:
            return self._glonass(m)
        if gnss in (System.GALILEO, System.BEIDOU):
            return self._galileo_beidou(m, System(gnss))
        if gnss != System.GPS:
            name = SHORT_NAME.get(System(gnss), str(gnss)) if gnss in KNOWN_SYSTEMS else str(gnss)
            self.counters[f"sfrbx_not_decoded_{name}"] += 1
            return None
        words = [int(getattr(m, f"dwrd_{i:02d}")) for i in range(1, int(m.numWords) + 1)]
        t_ref = self.t_gps_s
        if t_ref is None:
            self.counters["sfrbx_before_week"] += 1  # the 10-bit week needs a full week first
            return None
        eph = self.lnav.add(int(m.svId), words, t_ref)
        for k, v in self.lnav.counters.items():
            self.counters[k] = v
        return eph

    def _galileo_beidou(self, m: Any, system: System) -> KeplerEphemeris | None:
        words = [int(getattr(m, f"dwrd_{i:02d}")) for i in range(1, int(m.numWords) + 1)]
        eph: KeplerEphemeris | None
        if system == System.BEIDOU:
            eph = self.bdsnav.add(int(m.svId), words)
            counters = self.bdsnav.counters
        else:
            if self.t_gps_s is None:
                self.counters["sfrbx_before_week"] += 1  # toe is a second of week: the week from RAWX
                return None
            eph = self.inav.add(int(m.svId), words, self.t_gps_s)
            counters = self.inav.counters
        for k, v in counters.items():
            self.counters[k] = v
        return eph

    def _glonass(self, m: Any) -> GlonassEphemeris | None:
        if self.t_gps_s is None:
            self.counters["sfrbx_before_week"] += 1  # t_b is a time of day: the day comes from RAWX
            return None
        words = [int(getattr(m, f"dwrd_{i:02d}")) for i in range(1, int(m.numWords) + 1)]
        eph = self.glonav.add(int(m.svId), int(m.freqId) - 7, words, self.t_gps_s)
        for k, v in self.glonav.counters.items():
            self.counters[k] = v
        return eph

    def _pvt(self, m: Any) -> ReceiverPvt | None:
        speed_m_s = math.hypot(float(m.velN), float(m.velE), float(m.velD)) / 1e3
        if not (abs(float(m.lat)) <= 90.0 and abs(float(m.lon)) <= 180.0 and int(m.fixType) <= 5
                and abs(float(m.height)) <= 1e8 and speed_m_s <= 1000.0 and 0 <= int(m.iTOW) < 604_800_000):
            self.counters["pvt_out_of_range"] += 1  # heights within 100 km, speeds within 1 km/s
            return None
        t = gps_from_week_tow(self.week, float(m.iTOW) / 1e3) if self.week else math.nan
        t_utc = math.nan
        if int(getattr(m, "validDate", 0)) and int(getattr(m, "validTime", 0)):
            try:
                t_utc = gps_from_calendar(
                    int(m.year),
                    int(m.month),
                    int(m.day),
                    int(m.hour),
                    int(m.min),
                    int(m.second) + int(getattr(m, "nano", 0)) * 1e-9,
                    "UTC",
                )
            except Exception:  # noqa: BLE001 - an impossible date is only not used
                self.counters["pvt_bad_date"] += 1
        self.counters["pvt"] += 1
        return ReceiverPvt(
            t,
            int(m.fixType),
            float(m.lat),
            float(m.lon),
            float(m.height) / 1e3,
            float(m.hMSL) / 1e3,
            float(m.hAcc) / 1e3,
            float(m.vAcc) / 1e3,
            (float(m.velN) / 1e3, float(m.velE) / 1e3, float(m.velD) / 1e3),
            float(m.sAcc) / 1e3,
            int(m.numSV),
            float(m.pDOP),
            t_utc,
        )

    def _navsat(self, m: Any) -> None:
        for i in range(1, int(m.numSvs) + 1):
            s = f"_{i:02d}"
            self._sat[(int(getattr(m, "gnssId" + s)), int(getattr(m, "svId" + s)))] = (
                float(getattr(m, "elev" + s)),
                float(getattr(m, "azim" + s)),
            )
        self.counters["navsat"] += 1
