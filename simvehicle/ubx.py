"""The simulated receiver's output as u-blox UBX frames (pure: bytes out, no I/O).

Per measurement epoch, in a u-blox receiver's order: ``NAV-SAT`` (elevation, azimuth, C/N0, use
flags and residuals of every tracked satellite), ``RXM-RAWX`` (pseudorange, Doppler, C/N0, lock
time, the pseudorange σ as ``prStd``), ``NAV-PVT`` (the single-point fix) and, whenever a GPS
satellite has been tracked through a whole 6 s subframe, ``RXM-SFRBX`` with that LNAV subframe
(subframes 1-3: the ephemeris, 4: page 18, the Klobuchar parameters; built from the broadcast
ephemerides the simulator flies, quantised to their LNAV resolution, so a decoder recovers them
exactly). Packed here with ``struct`` (byte-equal to ``pyubx2``'s, tested; 20 times faster);
``pyubx2`` parses them and ``companion.gnss.ubx.UbxDecoder`` turns them back into the same
``GnssEpoch`` (a round trip exact to the UBX resolution: Doppler as float32 Hz).

Conventions (u-blox M8 interface description): ``rcvTow``/``week`` the receiver's clock reading
(GPS time + clock offset); ``recStat.clkReset`` after a 1 ms clock reset; GLONASS ``freqId`` =
channel + 7; ``locktime`` in ms (saturating at 64.5 s); ``doMes`` = −(pseudorange rate) / λ.
``NAV-PVT``: ``iTOW`` the solution's GPS time in ms, the date/time in UTC, ``height`` =
``hMSL`` (no geoid model: ellipsoidal heights throughout), ``hAcc`` the fix's 1σ per horizontal axis
(``GnssFix.h_acc_m``), ``vAcc`` its vertical 1σ, the Doppler velocity and its ``sAcc``.
``RXM-SFRBX`` GPS words: the 24 data bits as the satellite sent them (the receiver has resolved
their polarity) in bits 29..6, the six IS-GPS-200 parity bits in 5..0, the previous word's D29/D30
in bits 31..30. GLONASS strings 1-4 of every 30 s frame; Galileo E1-B I/NAV page pairs every 2 s
(``simvehicle.navmsg``: word types 2, 4 / 1, 3, 5 in the slots of the ICD's nominal subframe, word
type 0 in the others); BeiDou D1 subframes 1-5 every 6 s of BDT (4-5 without almanac). Not emitted:
GPS subframe 5 and the other subframe 4 pages (page 18 goes out in every subframe 4 slot, not once
in 12.5 minutes), GLONASS strings 5-15, BeiDou D2 (the simulated sky has no GEO satellite).
"""

from __future__ import annotations

import math
import struct
import time
from dataclasses import dataclass

import numpy as np

from companion.gnss.constants import C_M_S, DFREQ_G1_HZ, FREQ_B1I_HZ, FREQ_G1_HZ, FREQ_L1_HZ
from companion.gnss.ephemeris import EphemerisStore, GlonassEphemeris, KeplerEphemeris
from companion.gnss.geometry import ecef_to_geodetic, ecef_to_ned_matrix
from companion.gnss.glonav import hamming, moscow_day_start_gps_s, words_from_string
from companion.gnss.lnav import ura_index
from companion.gnss.observations import GnssEpoch
from companion.gnss.spp import SppSolution
from companion.gnss.systems import System
from companion.gnss.timescale import GPS_MINUS_BDT_S, gps_minus_utc_s, gps_to_bdt_s, gps_to_unix_s, week_tow
from simvehicle.navmsg import d1_subframe, inav_sfrbx_words, inav_word
from simvehicle.receiver import RawObservation, prstd_index

LNAV_PREAMBLE = 0x8B
SUBFRAME_S = 6.0
SC = math.pi
# IS-GPS-200 Table 20-XIV: the data bits (1-based) each parity bit D25..D30 sums, and which of the
# previous word's D29*/D30* starts it
PARITY_BITS: tuple[tuple[int, tuple[int, ...]], ...] = (
    (29, (1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23)),
    (30, (2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24)),
    (29, (1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22)),
    (30, (2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23)),
    (30, (1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24)),
    (29, (3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24)),
)
_MASKS = tuple((prev, sum(1 << (24 - i) for i in bits)) for prev, bits in PARITY_BITS)


def lnav_parity(data24: int, d29_prev: int, d30_prev: int) -> int:
    """The six parity bits D25..D30 of a word's 24 source data bits (IS-GPS-200 20.3.5.2)."""
    out = 0
    for prev, mask in _MASKS:
        v = (d29_prev if prev == 29 else d30_prev) ^ (bin(data24 & mask).count("1") & 1)
        out = (out << 1) | v
    return out


class _Bits:
    """240 data bits of a subframe, written by (position, width, value)."""

    def __init__(self) -> None:
        self.v = 0

    def put(self, pos: int, n: int, value: int) -> None:
        value &= (1 << n) - 1
        self.v |= value << (240 - pos - n)

    def scaled(self, pos: int, n: int, x: float, lsb: float) -> None:
        q = round(x / lsb)
        if not -(1 << n) < q < (1 << n):
            raise ValueError(f"LNAV field at bit {pos}: {x} does not fit {n} bits of {lsb}")
        self.put(pos, n, q)

    def words(self) -> list[int]:
        """Ten u-blox SFRBX words with parity; words 2 and 10 end in D29 = D30 = 0 (their last two
        data bits chosen for it, IS-GPS-200's "t" bits)."""
        data = [(self.v >> (240 - 24 * (i + 1))) & 0xFFFFFF for i in range(10)]
        out, d29, d30 = [], 0, 0
        for i, d in enumerate(data):
            if i in (1, 9):
                for t in range(4):
                    cand = (d & ~0x3) | t
                    if lnav_parity(cand, d29, d30) & 0x3 == 0:
                        d = cand
                        break
            par = lnav_parity(d, d29, d30)
            out.append((d29 << 31) | (d30 << 30) | (d << 6) | par)
            d29, d30 = (par >> 1) & 1, par & 1
        return out


def _header(b: _Bits, tow_next_s: float, subframe: int) -> None:
    b.put(0, 8, LNAV_PREAMBLE)
    b.put(24, 17, int(round(tow_next_s / SUBFRAME_S)) % 100800)
    b.put(43, 3, subframe)


def lnav_subframe(
    eph: KeplerEphemeris,
    subframe: int,
    tow_next_s: float,
    week: int,
    klobuchar: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[int] | None:
    """One LNAV subframe (1, 2, 3, or 4 page 18 when ``klobuchar`` is given) of ``eph`` as ten
    SFRBX words; ``tow_next_s`` the GPS second of week the next subframe starts at (HOW), ``week``
    the GPS week (sent modulo 1024). None for other subframes."""
    b = _Bits()
    _header(b, tow_next_s, subframe)
    if subframe == 1:
        b.put(48, 10, week % 1024)
        b.put(60, 4, ura_index(eph.accuracy_m))
        b.put(64, 6, eph.health)
        b.put(70, 2, (eph.iode >> 8) & 0x3)
        b.scaled(160, 8, eph.tgd_s, 2.0**-31)
        b.put(168, 8, eph.iode & 0xFF)
        b.put(176, 16, int(round((eph.toc_gps_s % 604800.0) / 16.0)))
        b.scaled(192, 8, eph.af2_s_s2, 2.0**-55)
        b.scaled(200, 16, eph.af1_s_s, 2.0**-43)
        b.scaled(216, 22, eph.af0_s, 2.0**-31)
    elif subframe == 2:
        b.put(48, 8, eph.iode & 0xFF)
        b.scaled(56, 16, eph.crs_m, 2.0**-5)
        b.scaled(72, 16, eph.delta_n_rad_s, 2.0**-43 * SC)
        b.scaled(88, 32, eph.m0_rad, 2.0**-31 * SC)
        b.scaled(120, 16, eph.cuc_rad, 2.0**-29)
        b.scaled(136, 32, eph.e, 2.0**-33)
        b.scaled(168, 16, eph.cus_rad, 2.0**-29)
        b.scaled(184, 32, eph.sqrt_a_m05, 2.0**-19)
        b.put(216, 16, int(round(eph.toe_sow_s / 16.0)))
    elif subframe == 3:
        b.scaled(48, 16, eph.cic_rad, 2.0**-29)
        b.scaled(64, 32, eph.omega0_rad, 2.0**-31 * SC)
        b.scaled(96, 16, eph.cis_rad, 2.0**-29)
        b.scaled(112, 32, eph.i0_rad, 2.0**-31 * SC)
        b.scaled(144, 16, eph.crc_m, 2.0**-5)
        b.scaled(160, 32, eph.omega_rad, 2.0**-31 * SC)
        b.scaled(192, 24, eph.omega_dot_rad_s, 2.0**-43 * SC)
        b.put(216, 8, eph.iode & 0xFF)
        b.scaled(224, 14, eph.idot_rad_s, 2.0**-43 * SC)
    elif subframe == 4 and klobuchar is not None:
        alpha, beta = klobuchar
        b.put(48, 2, 1)
        b.put(50, 6, 56)  # page 18: ionosphere and UTC
        for k, (lsb_a, lsb_b) in enumerate(
            ((2.0**-30, 2.0**11), (2.0**-27, 2.0**14), (2.0**-24, 2.0**16), (2.0**-24, 2.0**16))
        ):
            b.scaled(56 + 8 * k, 8, float(alpha[k]), lsb_a)
            b.scaled(88 + 8 * k, 8, float(beta[k]), lsb_b)
    else:
        return None
    return b.words()


def _wavelength_m(system: np.ndarray, channel: np.ndarray) -> np.ndarray:
    f = np.select(
        [system == System.GLONASS, system == System.BEIDOU],
        [FREQ_G1_HZ + channel * DFREQ_G1_HZ, np.full(len(system), FREQ_B1I_HZ)],
        FREQ_L1_HZ,
    )
    return C_M_S / f


def frame(msg_class: int, msg_id: int, payload: bytes) -> bytes:
    """A UBX frame: sync chars, class, id, little-endian length, payload, 8-bit Fletcher checksum."""
    body = struct.pack("<BBH", msg_class, msg_id, len(payload)) + payload
    a = b = 0
    for byte in body:
        a = (a + byte) & 0xFF
        b = (b + a) & 0xFF
    return b"\xb5\x62" + body + bytes((a, b))


RXM, NAV = 0x02, 0x01
RAWX, SFRBX, PVT, SAT = 0x15, 0x13, 0x07, 0x35
_RAWX_HEAD = struct.Struct("<dHbBB3x")
_RAWX_MEAS = struct.Struct("<ddfBBBBHBBBBBx")
_SAT_HEAD = struct.Struct("<IBB2x")
_SAT_SV = struct.Struct("<BBBbhhI")
_PVT = struct.Struct("<IHBBBBBBIiBBBBiiiiIIiiiiiIIHH4xihH")


def _i(x: float, scale: float = 1.0) -> int:
    """A scaled field as an integer (pyubx2's rounding), 0 for a value not known."""
    return int(round(x / scale)) if math.isfinite(x) else 0


def rawx(
    epoch: GnssEpoch, channel: np.ndarray, lock_ms: np.ndarray | None, clock_reset: bool = False
) -> bytes:
    """RXM-RAWX of an epoch (``channel``: GLONASS frequency channel per row, 0 for the others)."""
    week, tow = week_tow(epoch.t_gps_s)
    lam = _wavelength_m(epoch.system, channel)
    do_hz = -epoch.pseudorange_rate_m_s / lam
    sigma = np.sqrt(np.where(np.isfinite(epoch.pseudorange_var_m2), epoch.pseudorange_var_m2, 1e4))
    prstd = prstd_index(sigma).tolist()
    lock = (np.zeros(epoch.n) if lock_ms is None else np.clip(np.asarray(lock_ms), 0.0, 64500.0)).tolist()
    cn0 = np.clip(np.rint(np.nan_to_num(epoch.cn0_dbhz)), 0, 255).astype(int).tolist()
    rec_stat = 1 | (2 if clock_reset else 0)  # leapSec known, clkReset
    out = [_RAWX_HEAD.pack(tow, week, int(round(gps_minus_utc_s(epoch.t_gps_s))), epoch.n, rec_stat)]
    for i, (s, prn) in enumerate(zip(epoch.system.tolist(), epoch.prn.tolist(), strict=True)):
        d = float(do_hz[i])
        out.append(
            _RAWX_MEAS.pack(
                float(epoch.pseudorange_m[i]),
                0.0,
                d if math.isfinite(d) else 0.0,
                s,
                prn,
                0,
                int(channel[i]) + 7 if s == System.GLONASS else 0,
                int(lock[i]),
                cn0[i],
                prstd[i],
                15,
                8,
                1,
            )
        )
    return frame(RXM, RAWX, b"".join(out))


def navsat(epoch: GnssEpoch, itow_ms: int, solution: SppSolution | None) -> bytes:
    """NAV-SAT: every row's elevation, azimuth, C/N0; used and residual from the solution."""
    out = [_SAT_HEAD.pack(itow_ms, 1, epoch.n)]
    for i in range(epoch.n):
        used = bool(solution is not None and solution.used[i])
        res = float(solution.residuals_m[i]) if solution is not None else math.nan
        flags = (
            (7 if used else 4) | (int(used) << 3) | (1 << 8) | (1 << 11)
        )  # quality, used, orbit: eph, ephAvail
        out.append(
            _SAT_SV.pack(
                int(epoch.system[i]),
                int(epoch.prn[i]),
                int(np.clip(np.rint(np.nan_to_num(epoch.cn0_dbhz[i])), 0, 255)),
                int(np.clip(np.rint(np.nan_to_num(epoch.elevation_deg[i], nan=-91.0)), -91, 90)),
                int(np.rint(np.nan_to_num(epoch.azimuth_deg[i]))) % 360,
                _i(float(np.clip(res, -3276.0, 3276.0)), 0.1),
                flags,
            )
        )
    return frame(NAV, SAT, b"".join(out))


def navpvt(
    solution: SppSolution,
    lat_deg: float,
    lon_deg: float,
    height_m: float,
    v_ned_m_s: np.ndarray | None,
    h_acc_m: float,
    v_acc_m: float,
    t_gps_s: float,
) -> bytes:
    """NAV-PVT of a fix valid at GPS time ``t_gps_s`` (iTOW in ms; the date and time in UTC)."""
    _, tow = week_tow(t_gps_s)
    unix = gps_to_unix_s(t_gps_s)
    whole = math.floor(unix)
    tm = time.gmtime(whole)
    v = np.full(3, np.nan) if v_ned_m_s is None else np.asarray(v_ned_m_s, dtype=float)
    has_v = bool(np.isfinite(v).all())
    vn, ve, vd = (v if has_v else np.zeros(3)).tolist()
    speed = math.hypot(vn, ve)
    head = math.degrees(math.atan2(ve, vn)) % 360.0 if speed > 0.1 else 0.0
    pdop = float(solution.dops.pdop)
    payload = _PVT.pack(
        int(round(tow * 1000.0)) % 604_800_000,
        tm.tm_year,
        tm.tm_mon,
        tm.tm_mday,
        tm.tm_hour,
        tm.tm_min,
        tm.tm_sec,
        0b111,
        50,
        int(round((unix - whole) * 1e9)),
        3,
        1,
        0,
        solution.n_used,
        _i(lon_deg, 1e-7),
        _i(lat_deg, 1e-7),
        _i(height_m, 1e-3),
        _i(height_m, 1e-3),
        _i(h_acc_m, 1e-3),
        _i(v_acc_m, 1e-3),
        _i(vn, 1e-3),
        _i(ve, 1e-3),
        _i(vd, 1e-3),
        _i(speed, 1e-3),
        _i(head, 1e-5),
        _i(solution.vel_acc_m_s, 1e-3) if has_v else 0,
        _i(180.0, 1e-5),
        _i(min(pdop, 655.0), 0.01) if math.isfinite(pdop) else 9999,
        0,
        0,
        0,
        0,
    )
    return frame(NAV, PVT, payload)


def sfrbx(system: int, prn: int, words: list[int], freq_id: int = 0, sig_id: int = 0) -> bytes:
    """RXM-SFRBX (version 2) of one navigation message subframe (GLONASS: ``freq_id`` = channel + 7;
    ``sig_id`` the u-blox signal id: Galileo E1-B 1, the others' L1 signals 0)."""
    return frame(
        RXM, SFRBX,
        struct.pack(f"<BBBBBBBx{len(words)}I", system, prn, sig_id, freq_id, len(words), 0, 2, *words),
    )


GLONASS_STRING_S = 2.0
GLONASS_FRAME_S = 30.0
INAV_PAGE_S = 2.0
INAV_SUBFRAME_S = 30.0
# E1-B nominal subframe (Galileo OS SIS ICD Table 42): page slot -> the ephemeris word types sent
INAV_SUBFRAME_WORDS = {0: 2, 1: 4, 10: 1, 11: 3, 12: 5}
D1_SUBFRAME_S = 6.0
GALILEO_E1B_SIG_ID = 1  # u-blox signal identifiers: Galileo E1 C 0, E1 B 1


def _put_sm(value: float, lsb: float, hi: int, n: int) -> int:
    """A sign-magnitude field (GLONASS ICD) at string bit ``hi`` (bit k−1 = string bit k)."""
    q = int(round(value / lsb))
    if abs(q) >= 1 << (n - 1):
        raise ValueError(f"GLONASS field {value!r} out of range ({n} bits of {lsb!r})")
    return ((1 << (n - 1) if q < 0 else 0) | abs(q)) << (hi - n)


def glonass_string(eph: GlonassEphemeris, m: int, t_frame_gps_s: float, t_gps_s: float) -> int:
    """GLONASS string ``m`` (1-4) of the frame starting at ``t_frame_gps_s`` (ICD 5.1 4.4, the layout
    ``companion.gnss.glonav`` decodes), Hamming code included."""
    axis = m - 1
    s = m << 80
    if m <= 3:
        km = 1e3
        s |= _put_sm(eph.vel_ecef_m_s[axis] / km, 2.0**-20, 64, 24) | _put_sm(eph.acc_ecef_m_s2[axis] / km,
                                                                             2.0**-30, 40, 5)
        s |= _put_sm(eph.pos_ecef_m[axis] / km, 2.0**-11, 35, 27)
    day0 = moscow_day_start_gps_s(t_gps_s)
    if m == 1:
        tk = int(round(t_frame_gps_s - moscow_day_start_gps_s(t_frame_gps_s)))
        s |= ((tk // 3600) << 7 | (tk % 3600) // 60 << 1 | (tk % 60) // 30) << 64
    elif m == 2:
        tb = int(round((eph.toe_gps_s - moscow_day_start_gps_s(eph.toe_gps_s)) / 900.0))
        s |= (4 if eph.health else 0) << 77 | tb << 69
    elif m == 3:
        s |= _put_sm(eph.gamma_n, 2.0**-40, 79, 11)
    else:
        n_t = int(round((day0 - moscow_day_start_gps_s(0.0)) / 86400.0)) % 1461 + 1  # not decoded
        s |= _put_sm(-eph.clock_bias_s, 2.0**-30, 80, 22) | n_t << 15 | eph.prn << 10 | 1 << 8
    return hamming(s)


@dataclass
class UbxEncoder:
    """Frames of the receiver's epochs, in order (the GPS subframes each satellite completed)."""

    store: EphemerisStore
    frames: int = 0
    _last_t_gps_s: float | None = None

    def epoch_frames(self, raw: RawObservation) -> list[bytes]:
        """NAV-SAT, RXM-RAWX, NAV-PVT (when the epoch was solved) and the GPS subframes completed
        since the previous epoch."""
        ep = raw.epoch
        channel = np.where(ep.system == System.GLONASS, self.store.glonass_channel(ep.prn), 0)
        sol = raw.solution
        itow = int(round(week_tow(raw.t_gps_s)[1] * 1000.0)) % 604_800_000
        out = [navsat(ep, itow, sol), rawx(ep, channel, raw.lock_ms, raw.clock_reset)]
        if sol is not None:
            lat, lon, h = (float(x) for x in ecef_to_geodetic(sol.p_ecef_m))
            v = sol.v_ecef_m_s
            v_ned = ecef_to_ned_matrix(lat, lon) @ v if np.isfinite(v).all() else None
            out.append(
                navpvt(
                    sol, math.degrees(lat), math.degrees(lon), h, v_ned, sol.h_acc_m, sol.v_acc_m, raw.t_gps_s
                )
            )
        out += self._subframes(raw)
        self._last_t_gps_s = raw.t_gps_s
        self.frames += len(out)
        return out

    def _subframes(self, raw: RawObservation) -> list[bytes]:
        return self._gps_subframes(raw) + self._glonass_strings(raw) + self._galileo_pages(raw) + (
            self._beidou_subframes(raw))

    def _completed(self, raw: RawObservation, system: System, period_s: float,
                   offset_s: float = 0.0) -> tuple[float, list[tuple[int, int]]]:
        """The start of the ``period_s`` message slot (boundaries at ``offset_s`` + k·period) that
        ended since the previous epoch, with (prn, store row) of each ``system`` satellite tracked
        through all of it; (nan, []) when none ended."""
        t0, t1 = self._last_t_gps_s, raw.t_gps_s
        if t0 is None:
            return math.nan, []
        edge = math.floor((t1 - offset_s) / period_s) * period_s + offset_s
        if edge <= t0:
            return math.nan, []
        start = edge - period_s
        ep = raw.epoch
        lock = raw.lock_ms if raw.lock_ms is not None else np.zeros(ep.n)
        sel = (ep.system == system) & (lock >= (t1 - start) * 1000.0)
        rows = self.store.select(ep.system[sel], ep.prn[sel], np.full(int(sel.sum()), start))
        return start, [(p, r) for p, r in zip(ep.prn[sel].tolist(), rows.tolist(), strict=True)
                       if 0 <= r < self.store.n_kepler]

    def _galileo_pages(self, raw: RawObservation) -> list[bytes]:
        """The I/NAV page pair (2 s) each tracked Galileo satellite just completed."""
        start, sats = self._completed(raw, System.GALILEO, INAV_PAGE_S)
        if not sats:
            return []
        wtype = INAV_SUBFRAME_WORDS.get(int(round(start % INAV_SUBFRAME_S / INAV_PAGE_S)), 0)
        words = [inav_sfrbx_words(inav_word(self.store.kepler[row], wtype, start)) for _, row in sats]
        return [sfrbx(int(System.GALILEO), prn, w, sig_id=GALILEO_E1B_SIG_ID)
                for (prn, _), w in zip(sats, words, strict=True)]

    def _beidou_subframes(self, raw: RawObservation) -> list[bytes]:
        """The D1 subframe (6 s of BDT) each tracked BeiDou satellite just completed."""
        start, sats = self._completed(raw, System.BEIDOU, D1_SUBFRAME_S, GPS_MINUS_BDT_S)
        if not sats:
            return []
        t_bdt = gps_to_bdt_s(start)
        subframe = int(round(t_bdt / D1_SUBFRAME_S)) % 5 + 1
        return [sfrbx(int(System.BEIDOU), prn, d1_subframe(self.store.kepler[row], subframe, t_bdt))
                for prn, row in sats]

    def _glonass_strings(self, raw: RawObservation) -> list[bytes]:
        """Strings 1-4 (the ephemeris) of each GLONASS satellite tracked through the string that
        just ended (a string every 2 s, 15 to a 30 s frame)."""
        t0, t1 = self._last_t_gps_s, raw.t_gps_s
        if t0 is None or not self.store.glonass:
            return []
        edge = math.floor(t1 / GLONASS_STRING_S) * GLONASS_STRING_S
        if edge <= t0:
            return []
        start = edge - GLONASS_STRING_S
        day0 = moscow_day_start_gps_s(start)
        t_frame = day0 + math.floor((start - day0) / GLONASS_FRAME_S) * GLONASS_FRAME_S
        m = int(round((start - t_frame) / GLONASS_STRING_S)) + 1
        ep = raw.epoch
        lock = raw.lock_ms if raw.lock_ms is not None else np.zeros(ep.n)
        glo = (ep.system == System.GLONASS) & (lock >= (t1 - start) * 1000.0)
        if m > 4 or not glo.any():
            return []
        out = []
        frame_no = int(round((t_frame - day0) / GLONASS_FRAME_S))
        for prn in ep.prn[glo].tolist():
            eph = self._glonass_ephemeris(int(prn), t_frame)
            if eph is not None:
                string = glonass_string(eph, m, t_frame, start)
                words = words_from_string(string, frame_no // 5, frame_no % 5 + 1)
                out.append(sfrbx(int(System.GLONASS), int(prn), words, eph.channel + 7))
        return out

    def _glonass_ephemeris(self, slot: int, t_gps_s: float) -> GlonassEphemeris | None:
        """The set a satellite broadcasts at ``t_gps_s``: its t_b nearest."""
        best = None
        for e in self.store.glonass:
            if e.prn == slot and (best is None or abs(e.toe_gps_s - t_gps_s) < abs(best.toe_gps_s - t_gps_s)):
                best = e
        return best

    def _gps_subframes(self, raw: RawObservation) -> list[bytes]:
        start, sats = self._completed(raw, System.GPS, SUBFRAME_S)
        if not sats:
            return []
        week, tow_next = week_tow(start + SUBFRAME_S)
        subframe = int(round(tow_next / SUBFRAME_S) - 1) % 5 + 1  # the one that just ended
        out: list[bytes] = []
        for prn, row in sats:
            words = lnav_subframe(self.store.kepler[row], subframe, tow_next, week, self.store.klobuchar)
            if words is not None:
                out.append(sfrbx(int(System.GPS), prn, words))
        return out
