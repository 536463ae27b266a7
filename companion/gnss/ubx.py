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
* ``NAV-PVT`` -> :class:`ReceiverPvt` (the receiver's own solution with its accuracies).
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

    @property
    def klobuchar(self) -> tuple[np.ndarray, np.ndarray] | None:
        return self.lnav.klobuchar

    def feed(self, msg: Any) -> UbxItem | None:
        ident = getattr(msg, "identity", "")
        if ident == "RXM-RAWX":
            return self._rawx(msg)
        if ident == "RXM-SFRBX":
            return self._sfrbx(msg)
        if ident == "NAV-PVT":
            return self._pvt(msg)
        if ident == "NAV-SAT":
            self._navsat(msg)
            return None
        self.counters[f"ignored_{ident or 'unknown'}"] += 1
        return None

    def _rawx(self, m: Any) -> GnssEpoch | None:
        n = int(m.numMeas)
        tow, week = float(m.rcvTow), int(m.week)
        if not (math.isfinite(tow) and 0.0 <= tow < 604800.0 and week > 0):
            self.counters["rawx_bad_time"] += 1
            return None
        self.week = week
        t = gps_from_week_tow(week, tow)
        self.t_gps_s = t
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
            d = float(getattr(m, "doMes" + s))
            sysv.append(gnss)
            prnv.append(sv)
            pr.append(p)
            var.append((0.01 * 2.0 ** int(getattr(m, "prStd" + s, 0))) ** 2)
            rate.append(-lam * d if math.isfinite(d) else math.nan)
            cn0.append(float(getattr(m, "cno" + s)))
            e_a = self._sat.get((gnss, sv), (math.nan, math.nan))
            el.append(e_a[0])
            az.append(e_a[1])
        if not sysv:
            self.counters["rawx_empty"] += 1
            return None
        self.counters["rawx_epochs"] += 1
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

    def _pvt(self, m: Any) -> ReceiverPvt:
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
