"""GPS LNAV (L1 C/A) subframes -> broadcast ephemeris and Klobuchar parameters (IS-GPS-200 20.3.3).

Input: a subframe's ten 30-bit words as the u-blox RXM-SFRBX ``dwrd`` values (word in bits 29..0,
parity already resolved by the receiver), so each word's 24 data bits are ``dwrd >> 6``.
Subframes 1-3 with a matching issue of data give one :class:`KeplerEphemeris`; subframe 4 page 18
(SV id 56) gives the Klobuchar α/β. The URA index (subframe 1, 4 bits) -> ``accuracy_m``, the upper
bound of its interval (IS-GPS-200 20.3.3.3.1.3, as RTKLIB's table; inf for index 15, "no accuracy
prediction available": use at own risk). Not decoded: almanacs, UTC parameters, CNAV, and the Galileo,
BeiDou and GLONASS navigation messages (their SFRBX frames are counted, not used).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from companion.gnss.ephemeris import KeplerEphemeris
from companion.gnss.systems import System
from companion.gnss.timescale import resolve_week

PREAMBLE = 0x8B
SC2RAD = math.pi  # semicircles -> rad
# URA index -> metres: the upper bound of each index's interval (IS-GPS-200 20.3.3.3.1.3; BeiDou's
# ICD B1I 5.2.4.3 uses the same table); index 15 ("no accuracy prediction, use at own risk") -> inf
URA_M = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0, 3072.0, 6144.0)


def ura_m(index: int) -> float:
    return URA_M[index] if 0 <= index < len(URA_M) else math.inf


def ura_index(accuracy_m: float) -> int:
    """The smallest URA index whose value covers ``accuracy_m`` (15 when none does: inf, "no
    prediction"). NaN ("not given") has no index: a broadcast always states one (ValueError)."""
    if math.isnan(accuracy_m):
        raise ValueError("accuracy not given (NaN): a broadcast URA index states one")
    return next((i for i, u in enumerate(URA_M) if u >= accuracy_m), len(URA_M))


def _bits(words: Sequence[int]) -> int:
    """The 240 data bits of a subframe as one integer (word 1 bit 1 = most significant)."""
    v = 0
    for w in words:
        v = (v << 24) | ((int(w) >> 6) & 0xFFFFFF)
    return v


class _Reader:
    def __init__(self, words: Sequence[int]) -> None:
        self.v = _bits(words)

    def u(self, pos: int, n: int) -> int:
        """Unsigned field of n bits at data bit ``pos`` (0 = first bit of word 1)."""
        return (self.v >> (240 - pos - n)) & ((1 << n) - 1)

    def s(self, pos: int, n: int) -> int:
        x = self.u(pos, n)
        return x - (1 << n) if x >> (n - 1) else x


def subframe_id(words: Sequence[int]) -> int:
    """Subframe ID (1-5) from the HOW; 0 when the preamble is wrong."""
    r = _Reader(words)
    return r.u(43, 3) if r.u(0, 8) == PREAMBLE else 0


@dataclass
class LnavDecoder:
    """Collects subframes per satellite; ``add`` returns an ephemeris once 1-3 agree."""

    t_ref_gps_s: float = 0.0  # resolves the 10-bit week (the receiver's current time)
    frames: dict[int, dict[int, list[int]]] = field(default_factory=dict)
    klobuchar: tuple[np.ndarray, np.ndarray] | None = None
    counters: dict[str, int] = field(default_factory=dict)

    def _count(self, name: str) -> None:
        self.counters[name] = self.counters.get(name, 0) + 1

    def add(self, prn: int, words: Sequence[int], t_ref_gps_s: float | None = None) -> KeplerEphemeris | None:
        if t_ref_gps_s is not None:
            self.t_ref_gps_s = t_ref_gps_s
        if len(words) != 10:
            self._count("lnav_bad_length")
            return None
        sid = subframe_id(words)
        if sid == 0:
            self._count("lnav_bad_preamble")
            return None
        if sid == 4:
            self._subframe4(words)
            return None
        if sid not in (1, 2, 3):
            return None
        sv = self.frames.setdefault(prn, {})
        sv[sid] = list(words)
        if len(sv) == 3:
            eph = decode_ephemeris(prn, sv[1], sv[2], sv[3], self.t_ref_gps_s)
            if eph is not None:
                self._count("lnav_ephemerides")
                self.frames[prn] = {}
                return eph
            self._count("lnav_iode_mismatch")
        return None

    def _subframe4(self, words: Sequence[int]) -> None:
        r = _Reader(words)
        if r.u(50, 6) != 56:  # page 18: ionosphere and UTC
            return
        alpha = np.array(
            [r.s(56, 8) * 2.0**-30, r.s(64, 8) * 2.0**-27, r.s(72, 8) * 2.0**-24, r.s(80, 8) * 2.0**-24]
        )
        beta = np.array(
            [r.s(88, 8) * 2.0**11, r.s(96, 8) * 2.0**14, r.s(104, 8) * 2.0**16, r.s(112, 8) * 2.0**16]
        )
        self.klobuchar = (alpha, beta)
        self._count("lnav_klobuchar")


def decode_ephemeris(
    prn: int, sf1: Sequence[int], sf2: Sequence[int], sf3: Sequence[int], t_ref_gps_s: float
) -> KeplerEphemeris | None:
    """Subframes 1, 2, 3 -> ephemeris; None when their issues of data differ (a cut-over)."""
    a, b, c = _Reader(sf1), _Reader(sf2), _Reader(sf3)
    week10 = a.u(48, 10)
    ura = a.u(60, 4)
    health = a.u(64, 6)
    iodc = (a.u(70, 2) << 8) | a.u(168, 8)
    tgd = a.s(160, 8) * 2.0**-31
    toc_sow = a.u(176, 16) * 16.0
    af2 = a.s(192, 8) * 2.0**-55
    af1 = a.s(200, 16) * 2.0**-43
    af0 = a.s(216, 22) * 2.0**-31
    iode2 = b.u(48, 8)
    crs = b.s(56, 16) * 2.0**-5
    deln = b.s(72, 16) * 2.0**-43 * SC2RAD
    m0 = b.s(88, 32) * 2.0**-31 * SC2RAD
    cuc = b.s(120, 16) * 2.0**-29
    e = b.u(136, 32) * 2.0**-33
    cus = b.s(168, 16) * 2.0**-29
    sqrt_a = b.u(184, 32) * 2.0**-19
    toe_sow = b.u(216, 16) * 16.0
    cic = c.s(48, 16) * 2.0**-29
    omega0 = c.s(64, 32) * 2.0**-31 * SC2RAD
    cis = c.s(96, 16) * 2.0**-29
    i0 = c.s(112, 32) * 2.0**-31 * SC2RAD
    crc = c.s(144, 16) * 2.0**-5
    omega = c.s(160, 32) * 2.0**-31 * SC2RAD
    omega_dot = c.s(192, 24) * 2.0**-43 * SC2RAD
    iode3 = c.u(216, 8)
    idot = c.s(224, 14) * 2.0**-43 * SC2RAD
    if not (iode2 == iode3 == (iodc & 0xFF)):
        return None
    week = resolve_week(week10, 1024, t_ref_gps_s)
    toe = week * 604800.0 + toe_sow
    toc = week * 604800.0 + toc_sow
    # toe/toc may sit in the next/previous week relative to the transmitted week number
    toe += 604800.0 * round((t_ref_gps_s - toe) / 604800.0) if t_ref_gps_s > 0 else 0.0
    toc += 604800.0 * round((toe - toc) / 604800.0)
    return KeplerEphemeris(
        system=int(System.GPS), prn=int(prn), toe_gps_s=toe, toc_gps_s=toc, toe_sow_s=toe_sow,
        sqrt_a_m05=sqrt_a, e=e, i0_rad=i0, omega0_rad=omega0, omega_rad=omega, m0_rad=m0, delta_n_rad_s=deln,
        omega_dot_rad_s=omega_dot, idot_rad_s=idot, cuc_rad=cuc, cus_rad=cus, crc_m=crc, crs_m=crs,
        cic_rad=cic, cis_rad=cis, af0_s=af0, af1_s_s=af1, af2_s_s2=af2, tgd_s=tgd, iode=iode2, health=health,
        accuracy_m=ura_m(ura))
