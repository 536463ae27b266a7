"""BeiDou D1 (B1I, MEO/IGSO) and D2 (GEO) navigation messages -> broadcast ephemeris (BeiDou ICD B1I 3.0,
5.2 and 5.3).

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
of data (``iode``), URAI -> ``accuracy_m`` (the GPS URA table, ``lnav.ura_m``: inf for 15). Times: BDT
week (13 bits) and seconds, BDT = GPS − 14 s.

The GEO satellites (C01-C05, C59-C63) send D2 instead: subframe 1's pages 1, 3-10 (one page every 3 s,
a 30 s cycle; page 2 is the ionosphere grid) carry the same fields at the same scale factors, several
split across pages (``D2_FIELDS``: the pages concatenated); SOW 3 s per page apart and toc = toe are
their consistency test. Not decoded: D1 subframes 4-5 and D2 subframes 2-5 (almanac, integrity,
time offsets; counted ``beidou_other_subframe`` / ``beidou_d2_other``), the BeiDou Klobuchar set, TGD2.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from companion.gnss.ephemeris import KeplerEphemeris
from companion.gnss.lnav import ura_m
from companion.gnss.navbits import SC, BitReader, Field, from_words, get_all, split
from companion.gnss.navbits import field as f
from companion.gnss.systems import System, is_beidou_geo
from companion.gnss.timescale import bdt_to_gps_s

SUBFRAME_BITS = 300
PREAMBLE = 0b11100010010
WEEK_S = 604800.0
BCH_POLY = 0b10011  # x⁴ + x + 1

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


# D2 (GEO): subframe 1's ten pages (3 s apart) concatenated, page p at bits 300·(p − 1) onwards; the
# fields as RTKLIB's ``decode_bds_d2`` reads them (ICD 5.3.3), several split across pages
D2_PAGES = 10


def _d2(page: int, bit: int, n: int) -> tuple[int, int]:
    return SUBFRAME_BITS * (page - 1) + bit, n


PNUM = f(42, 4)
D2_SATH1, D2_AODC, D2_URAI, D2_WN = f(46, 1), f(47, 5), f(60, 4), f(64, 13)
D2_TOC = split((77, 5), (90, 12), lsb=8.0)
D2_TGD1 = f(102, 10, 1e-10, True)
D2_AODE = split(_d2(4, 91, 5))
D2_TOE = split(_d2(7, 80, 2), _d2(7, 90, 15), lsb=8.0)
D2_FIELDS: dict[str, Field] = {
    "af0_s": split(_d2(3, 100, 12), _d2(3, 120, 12), lsb=2.0**-33, signed=True),
    "af1_s_s": split(_d2(3, 132, 4), _d2(4, 46, 6), _d2(4, 60, 12), lsb=2.0**-50, signed=True),
    "af2_s_s2": split(_d2(4, 72, 10), _d2(4, 90, 1), lsb=2.0**-66, signed=True),
    "delta_n_rad_s": split(_d2(4, 96, 16), lsb=2.0**-43 * SC, signed=True),
    "cuc_rad": split(_d2(4, 120, 14), _d2(5, 46, 4), lsb=2.0**-31, signed=True),
    "m0_rad": split(_d2(5, 50, 2), _d2(5, 60, 22), _d2(5, 90, 8), lsb=2.0**-31 * SC, signed=True),
    "cus_rad": split(_d2(5, 98, 14), _d2(5, 120, 4), lsb=2.0**-31, signed=True),
    "e": split(_d2(5, 124, 10), _d2(6, 46, 6), _d2(6, 60, 16), lsb=2.0**-33),
    "sqrt_a_m05": split(_d2(6, 76, 6), _d2(6, 90, 22), _d2(6, 120, 4), lsb=2.0**-19),
    "cic_rad": split(_d2(6, 124, 10), _d2(7, 46, 6), _d2(7, 60, 2), lsb=2.0**-31, signed=True),
    "cis_rad": split(_d2(7, 62, 18), lsb=2.0**-31, signed=True),
    "i0_rad": split(_d2(7, 105, 7), _d2(7, 120, 14), _d2(8, 46, 6), _d2(8, 60, 5), lsb=2.0**-31 * SC,
                    signed=True),
    "crc_m": split(_d2(8, 65, 17), _d2(8, 90, 1), lsb=2.0**-6, signed=True),
    "crs_m": split(_d2(8, 91, 18), lsb=2.0**-6, signed=True),
    "omega_dot_rad_s": split(_d2(8, 109, 3), _d2(8, 120, 16), _d2(9, 46, 5), lsb=2.0**-43 * SC, signed=True),
    "omega0_rad": split(_d2(9, 51, 1), _d2(9, 60, 22), _d2(9, 90, 9), lsb=2.0**-31 * SC, signed=True),
    "omega_rad": split(_d2(9, 99, 13), _d2(9, 120, 14), _d2(10, 46, 5), lsb=2.0**-31 * SC, signed=True),
    "idot_rad_s": split(_d2(10, 51, 1), _d2(10, 60, 13), lsb=2.0**-43 * SC, signed=True),
}
D2_EPHEMERIS_PAGES = (1, 3, 4, 5, 6, 7, 8, 9, 10)  # page 2: the ionosphere grid


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
    """Collects D1 subframes 1-3 (MEO/IGSO) or D2 subframe 1 pages 1, 3-10 (GEO) per satellite;
    ``add`` returns an ephemeris once those of one frame (D2: one 30 s page cycle) agree."""

    frames: dict[int, dict[int, int]] = field(default_factory=dict)
    d2_pages: dict[int, dict[int, int]] = field(default_factory=dict)
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
        sid = r.raw(FRAID)
        if bool(is_beidou_geo(np.array([prn]))[0]):
            return self._d2_page(prn, sid, r)
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


    def _d2_page(self, prn: int, sid: int, r: BitReader) -> KeplerEphemeris | None:
        """A GEO satellite's D2 subframe: pages 1, 3-10 of subframe 1 make an ephemeris."""
        page = r.raw(PNUM)
        if sid != 1 or page not in D2_EPHEMERIS_PAGES:
            self._count("beidou_d2_other")  # subframes 2-5 (integrity, almanac) and page 2 (ionosphere)
            return None
        got = self.d2_pages.setdefault(prn, {})
        got[page] = r.v
        if len(got) < len(D2_EPHEMERIS_PAGES):
            return None
        eph = decode_d2_ephemeris(prn, [got[p] for p in D2_EPHEMERIS_PAGES])
        if eph is None:
            self._count("beidou_inconsistent")
            del got[min(got, key=lambda k: BitReader(got[k], SUBFRAME_BITS).raw(SOW))]
            return None
        self.d2_pages[prn] = {}
        self._count("beidou_ephemerides")
        return eph


def _ephemeris(prn: int, week: int, sow1: int, toe_sow: float, clock_orbit: dict[str, float], tgd_s: float,
               iode: int, health: int, urai: int) -> KeplerEphemeris:
    """The ephemeris from the decoded values (BDT week and SOW of the first subframe/page)."""
    toe_bdt = week * WEEK_S + toe_sow
    toe_bdt += WEEK_S * round((week * WEEK_S + sow1 - toe_bdt) / WEEK_S)  # toe in the next/previous week
    toe = bdt_to_gps_s(toe_bdt)
    return KeplerEphemeris(
        system=int(System.BEIDOU), prn=int(prn), toe_gps_s=toe, toc_gps_s=toe, toe_sow_s=toe_sow,
        tgd_s=tgd_s, iode=iode, health=health, accuracy_m=ura_m(urai), **clock_orbit)


def decode_d2_ephemeris(prn: int, pages: Sequence[int]) -> KeplerEphemeris | None:
    """D2 subframe 1 pages 1, 3-10 (300-bit integers) -> ephemeris; None unless they are one
    cycle's (SOW 3 s per page apart) and toc = toe."""
    r = [BitReader(x, SUBFRAME_BITS) for x in pages]
    sow1 = r[0].raw(SOW)
    if any(rp.raw(SOW) != sow1 + 3 * (p - 1) for rp, p in zip(r, D2_EPHEMERIS_PAGES, strict=True)):
        return None
    whole = {1: pages[0], 2: 0} | dict(zip(D2_EPHEMERIS_PAGES[1:], pages[1:], strict=True))
    cat = BitReader(from_words([whole[p] for p in range(1, D2_PAGES + 1)], SUBFRAME_BITS),
                    SUBFRAME_BITS * D2_PAGES)
    toe_sow = cat.get(D2_TOE)
    if r[0].get(D2_TOC) != toe_sow:
        return None
    return _ephemeris(prn, r[0].raw(D2_WN), sow1, toe_sow, get_all(cat, D2_FIELDS), r[0].get(D2_TGD1),
                      cat.raw(D2_AODE), r[0].raw(D2_SATH1), r[0].raw(D2_URAI))


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
    v = get_all(a, CLOCK) | get_all(b, ORBIT_2) | get_all(c, ORBIT_3)
    return _ephemeris(prn, a.raw(WN), sow1, toe_sow, v, a.get(TGD1), a.raw(AODE), a.raw(SATH1), a.raw(URAI))
