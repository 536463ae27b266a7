"""BeiDou D1 navigation message (B1I, MEO/IGSO satellites) -> broadcast ephemeris (BeiDou ICD B1I 3.0, 5.2).

Input: a u-blox RXM-SFRBX of BeiDou B1I: a subframe's ten 30-bit words in bits 29..0 of each word
(u-blox integration manuals, "BeiDou": the words in the order received, the top two bits padding),
de-interleaved and with their parity bits: word 1 = 15 plain bits (preamble 11100010010, 4
reserved) + one BCH(15,11) code word; words 2-10 = 11 information bits of the first code word, 11 of
the second, the 4 parity bits of the first, the 4 of the second (the layout RTKLIB's
``decode_bds_d1`` and PocketSDR's de-interleaver use; confirmed on a real C10 subframe in the tests).
Every code word is checked (generator x⁴ + x + 1, ICD 5.1.3); a subframe with one failing is counted
(``beidou_bad_parity``) and not used.

Subframes 1-3 of one frame (SOW 6 s apart, subframe 1's toc equal to the toe of 2-3: the D1
message has no issue of data in subframes 2-3, so this is its consistency test, as RTKLIB's) give
one :class:`KeplerEphemeris`. Fields and scale factors (ICD 5.2.4; bit positions within the 300-bit
subframe, parity bits included, as RTKLIB's): toe/toc 2³ s (BDT), a0 2⁻³³ s, a1 2⁻⁵⁰ s/s, a2 2⁻⁶⁶ s/s²,
TGD1 0.1 ns (the B1I group delay, ``tgd_s``), √A 2⁻¹⁹, e 2⁻³³, M0/Ω0/i0/ω 2⁻³¹ semicircles, Δn/Ω̇/IDOT
2⁻⁴³ semicircles/s, Cuc/Cus/Cic/Cis 2⁻³¹ rad, Crc/Crs 2⁻⁶ m; SatH1 the health (0 good), AODE the issue
of data (``iode``), URAI -> ``accuracy_m`` (the GPS URA table, inf for 15). Times: BDT week (13 bits)
and seconds, BDT = GPS − 14 s. Not decoded: subframes 4-5 (almanac), the BeiDou Klobuchar set, and
the D2 message of the GEO satellites (C01-C05, C59-C63: counted as ``beidou_d2_not_decoded``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from companion.gnss.ephemeris import KeplerEphemeris
from companion.gnss.navbits import SC, BitReader, Field, from_words, get_all, split
from companion.gnss.navbits import field as f
from companion.gnss.systems import System, is_beidou_geo
from companion.gnss.timescale import bdt_to_gps_s

SUBFRAME_BITS = 300
PREAMBLE = 0b11100010010
WEEK_S = 604800.0
BCH_POLY = 0b10011  # x⁴ + x + 1
# URA index -> metres (ICD B1I 5.2.4.3, the GPS table)
URA_M = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0, 3072.0, 6144.0)

FRAID = f(15, 3)
SOW = split((18, 8), (30, 12))
# subframe 1
SATH1, AODC, URAI, WN = f(42, 1), f(43, 5), f(48, 4), f(60, 13)
TOC = split((73, 9), (90, 8), lsb=8.0)
TGD1 = f(98, 10, 1e-10, True)
TGD2 = split((108, 4), (120, 6), lsb=1e-10, signed=True)
AODE = f(287, 5)
CLOCK: dict[str, Field] = {
    "af2_s_s2": f(214, 11, 2.0**-66, True),
    "af0_s": split((225, 7), (240, 17), lsb=2.0**-33, signed=True),
    "af1_s_s": split((257, 5), (270, 17), lsb=2.0**-50, signed=True),
}
ORBIT_2: dict[str, Field] = {
    "delta_n_rad_s": split((42, 10), (60, 6), lsb=2.0**-43 * SC, signed=True),
    "cuc_rad": split((66, 16), (90, 2), lsb=2.0**-31, signed=True),
    "m0_rad": split((92, 20), (120, 12), lsb=2.0**-31 * SC, signed=True),
    "e": split((132, 10), (150, 22), lsb=2.0**-33),
    "cus_rad": f(180, 18, 2.0**-31, True),
    "crc_m": split((198, 4), (210, 14), lsb=2.0**-6, signed=True),
    "crs_m": split((224, 8), (240, 10), lsb=2.0**-6, signed=True),
    "sqrt_a_m05": split((250, 12), (270, 20), lsb=2.0**-19),
}
TOE_MSB = f(290, 2)  # subframe 2
TOE_LSB = split((42, 10), (60, 5))  # subframe 3
ORBIT_3: dict[str, Field] = {
    "i0_rad": split((65, 17), (90, 15), lsb=2.0**-31 * SC, signed=True),
    "cic_rad": split((105, 7), (120, 11), lsb=2.0**-31, signed=True),
    "omega_dot_rad_s": split((131, 11), (150, 13), lsb=2.0**-43 * SC, signed=True),
    "cis_rad": split((163, 9), (180, 9), lsb=2.0**-31, signed=True),
    "idot_rad_s": split((189, 13), (210, 1), lsb=2.0**-43 * SC, signed=True),
    "omega0_rad": split((211, 21), (240, 11), lsb=2.0**-31 * SC, signed=True),
    "omega_rad": split((251, 11), (270, 21), lsb=2.0**-31 * SC, signed=True),
}


def ura_m(index: int) -> float:
    return URA_M[index] if 0 <= index < len(URA_M) else math.inf


def ura_index(accuracy_m: float) -> int:
    """The smallest URA index whose value covers ``accuracy_m`` (15 when none does)."""
    return next((i for i, u in enumerate(URA_M) if u >= accuracy_m), len(URA_M))


def bch_parity(info11: int) -> int:
    """The 4 parity bits of an 11-bit BCH(15,11) information word (remainder of info·x⁴ by x⁴+x+1)."""
    r = (info11 & 0x7FF) << 4
    for i in range(14, 3, -1):
        if r >> i & 1:
            r ^= BCH_POLY << (i - 4)
    return r


def word_parity_ok(k: int, word: int) -> bool:
    """Word ``k`` (0-based) of a subframe passes its BCH check(s)."""
    if k == 0:
        return bch_parity((word >> 4) & 0x7FF) == word & 0xF
    return (bch_parity((word >> 19) & 0x7FF) == (word >> 4) & 0xF
            and bch_parity((word >> 8) & 0x7FF) == word & 0xF)


def with_parity(k: int, word: int) -> int:
    """Word ``k`` with its parity bits set from its information bits."""
    if k == 0:
        return (word & ~0xF) | bch_parity((word >> 4) & 0x7FF)
    return (word & ~0xFF) | bch_parity((word >> 19) & 0x7FF) << 4 | bch_parity((word >> 8) & 0x7FF)


@dataclass
class BeidouDecoder:
    """Collects D1 subframes 1-3 per satellite; ``add`` returns an ephemeris once three of one frame
    agree."""

    frames: dict[int, dict[int, int]] = field(default_factory=dict)
    counters: dict[str, int] = field(default_factory=dict)

    def _count(self, name: str) -> None:
        self.counters[name] = self.counters.get(name, 0) + 1

    def add(self, prn: int, words: Sequence[int]) -> KeplerEphemeris | None:
        if len(words) != 10:
            self._count("beidou_bad_length")
            return None
        w = [int(x) & 0x3FFFFFFF for x in words]
        if not all(word_parity_ok(k, x) for k, x in enumerate(w)):
            self._count("beidou_bad_parity")
            return None
        v = from_words(w, 30)
        r = BitReader(v, SUBFRAME_BITS)
        if r.u(0, 11) != PREAMBLE:
            self._count("beidou_bad_preamble")
            return None
        if bool(is_beidou_geo(np.array([prn]))[0]):
            self._count("beidou_d2_not_decoded")  # GEO: the D2 message (subframe 1 in ten pages)
            return None
        sid = r.raw(FRAID)
        if sid not in (1, 2, 3):
            self._count("beidou_other_subframe")  # 4-5: almanac, time offsets; 0, 6, 7: not defined
            return None
        got = self.frames.setdefault(prn, {})
        got[sid] = v
        if len(got) < 3:
            return None
        eph = decode_ephemeris(prn, got[1], got[2], got[3])
        if eph is None:
            self._count("beidou_inconsistent")  # a frame boundary or an upload between the three
            del got[min(got, key=lambda k: BitReader(got[k], SUBFRAME_BITS).raw(SOW))]
            return None
        self.frames[prn] = {}
        self._count("beidou_ephemerides")
        return eph


def decode_ephemeris(prn: int, sf1: int, sf2: int, sf3: int) -> KeplerEphemeris | None:
    """Subframes 1-3 (300-bit integers) -> ephemeris; None unless they are one frame's (SOW 6 s
    apart) and toc = toe."""
    a, b, c = (BitReader(x, SUBFRAME_BITS) for x in (sf1, sf2, sf3))
    sow1 = a.raw(SOW)
    if b.raw(SOW) != sow1 + 6 or c.raw(SOW) != sow1 + 12:
        return None
    toe_sow = float(((b.raw(TOE_MSB) << 15) | c.raw(TOE_LSB)) * 8)
    if a.get(TOC) != toe_sow:
        return None
    week = a.raw(WN)
    toe_bdt = week * WEEK_S + toe_sow
    toe_bdt += WEEK_S * round((week * WEEK_S + sow1 - toe_bdt) / WEEK_S)  # toe in the next/previous week
    v = get_all(a, CLOCK) | get_all(b, ORBIT_2) | get_all(c, ORBIT_3)
    toe = bdt_to_gps_s(toe_bdt)
    return KeplerEphemeris(
        system=int(System.BEIDOU), prn=int(prn), toe_gps_s=toe, toc_gps_s=toe, toe_sow_s=toe_sow,
        tgd_s=a.get(TGD1), iode=a.raw(AODE), health=a.raw(SATH1), accuracy_m=ura_m(a.raw(URAI)), **v)
