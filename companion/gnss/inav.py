"""Galileo I/NAV (E1-B) page pairs -> broadcast ephemeris (Galileo OS SIS ICD 2.0, 4.3).

Input: a u-blox RXM-SFRBX of a Galileo E1 signal: eight 32-bit words, words 0-3 the even page part
and words 4-7 the odd part, each part's 120 bits from the most significant bit on (u-blox interface
description, "Galileo E1-B"; RTKLIB reads them the same way). Even part: even/odd flag (0), page
type (0 nominal, 1 alert), data 1/2 (112 bits), tail. Odd part: flag (1), page type, data 2/2 (16
bits), reserved (40), SAR (22), spare (2), CRC (24), reserved (8), tail. The CRC-24Q covers the
196 bits from the even flag to the odd spare (ICD 4.3.3; four zero bits pad them to 25 bytes). The
112 + 16 data bits are one 128-bit *word*; word types 1-4 carry the ephemeris (all four with the
same IODnav), word type 5 the ionosphere, the group delays, the health flags, WN and TOW.

Scale factors (ICD Tables 60, 63, 64, 66, 68, 70; the same as RTKLIB's ``decode_gal_inav``): toe and
toc 60 s; M0, Ω0, i0, ω 2⁻³¹ semicircles; e 2⁻³³; √A 2⁻¹⁹ m^½; Ω̇, Δn, IDOT 2⁻⁴³ semicircles/s;
Cuc, Cus, Cic, Cis 2⁻²⁹ rad; Crc, Crs 2⁻⁵ m; af0 2⁻³⁴ s, af1 2⁻⁴⁶ s/s, af2 2⁻⁵⁹ s/s²; BGD 2⁻³² s.
The clock (af0-af2) is the E1/E5b pair's; an E1 user subtracts BGD(E1,E5b) (``tgd_s``). Health as
RINEX writes it (and the RINEX reader passes on): bit 0 E1-B DVS, bits 1-2 E1-B HS, bit 6 E5b DVS,
bits 7-8 E5b HS; anything set makes the ephemeris unhealthy. SISA (ICD Table 89) -> ``accuracy_m``
(inf for "no accuracy prediction available"). ``toe`` is placed in the GST (= GPS) week nearest the
receiver's time. Not decoded: almanacs (word types 7-10), GST-UTC (6), the ionosphere (NeQuick),
reduced CED and OSNMA.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from pyrtcm.rtcmhelpers import calc_crc24q

from companion.gnss.ephemeris import KeplerEphemeris
from companion.gnss.navbits import SC, BitReader, Field, from_words, get_all
from companion.gnss.navbits import field as f
from companion.gnss.systems import System

PART_BITS = 120
WORD_BITS = 128
WEEK_S = 604800.0
IODNAV = f(6, 10)
WORD_TYPE = f(0, 6)
# the ephemeris fields of word types 1-4 (bit positions within the 128-bit word)
EPHEMERIS_WORDS: dict[int, dict[str, Field]] = {
    1: {"toe_sow_s": f(16, 14, 60.0), "m0_rad": f(30, 32, 2.0**-31 * SC, True), "e": f(62, 32, 2.0**-33),
        "sqrt_a_m05": f(94, 32, 2.0**-19)},
    2: {"omega0_rad": f(16, 32, 2.0**-31 * SC, True), "i0_rad": f(48, 32, 2.0**-31 * SC, True),
        "omega_rad": f(80, 32, 2.0**-31 * SC, True), "idot_rad_s": f(112, 14, 2.0**-43 * SC, True)},
    3: {"omega_dot_rad_s": f(16, 24, 2.0**-43 * SC, True), "delta_n_rad_s": f(40, 16, 2.0**-43 * SC, True),
        "cuc_rad": f(56, 16, 2.0**-29, True), "cus_rad": f(72, 16, 2.0**-29, True),
        "crc_m": f(88, 16, 2.0**-5, True), "crs_m": f(104, 16, 2.0**-5, True)},
    4: {"cic_rad": f(22, 16, 2.0**-29, True), "cis_rad": f(38, 16, 2.0**-29, True),
        "toc_sow_s": f(54, 14, 60.0),
        "af0_s": f(68, 31, 2.0**-34, True), "af1_s_s": f(99, 21, 2.0**-46, True),
        "af2_s_s2": f(120, 6, 2.0**-59, True)},
}
SISA = f(120, 8)  # word type 3
SVID = f(16, 6)  # word type 4
# word type 5
BGD_E1E5A = f(47, 10, 2.0**-32, True)
BGD_E1E5B = f(57, 10, 2.0**-32, True)
E5B_HS, E1B_HS, E5B_DVS, E1B_DVS = f(67, 2), f(69, 2), f(71, 1), f(72, 1)
WN, TOW = f(73, 12), f(85, 20)
ODD_CRC = (82, 24)
SISA_NAPA = 255


def sisa_m(index: int) -> float:
    """SISA index -> metres (ICD Table 89); inf for spare indices and NAPA (255)."""
    if index < 50:
        return index * 0.01
    if index < 75:
        return 0.5 + (index - 50) * 0.02
    if index < 100:
        return 1.0 + (index - 75) * 0.04
    if index < 126:
        return 2.0 + (index - 100) * 0.16
    return math.inf


def sisa_index(accuracy_m: float) -> int:
    """The smallest SISA index whose value covers ``accuracy_m`` (NAPA when none does: inf, "no
    prediction"). NaN ("not given") has no index: a broadcast always states one (ValueError)."""
    if math.isnan(accuracy_m):
        raise ValueError("accuracy not given (NaN): a broadcast SISA index states one")
    for i in range(126):
        if sisa_m(i) >= accuracy_m - 1e-9:
            return i
    return SISA_NAPA


def crc_bytes(even: int, odd: int) -> bytes:
    """The CRC-protected 196 bits (even bits 0-113, odd bits 0-81) after four zero bits: 25 bytes."""
    v = ((even >> (PART_BITS - 114)) << 82) | (odd >> (PART_BITS - 82))
    return v.to_bytes(25, "big")


def page_crc(even: int, odd: int) -> int:
    return calc_crc24q(crc_bytes(even, odd))


def parts_from_words(words: Sequence[int]) -> tuple[int, int]:
    """The even and odd 120-bit page parts of a u-blox SFRBX's eight words."""
    return (from_words(words[:4], 32) >> 8), (from_words(words[4:8], 32) >> 8)


def word_from_parts(even: int, odd: int) -> int:
    """The 128-bit I/NAV word: the even part's 112 data bits and the odd part's 16."""
    r_even, r_odd = BitReader(even, PART_BITS), BitReader(odd, PART_BITS)
    return (r_even.u(2, 112) << 16) | r_odd.u(2, 16)


@dataclass
class GalileoDecoder:
    """Collects I/NAV words per satellite; ``add`` returns an ephemeris once word types 1-4 of one
    IODnav and a word type 5 are in (then starts again: each set with the word 5 received with it)."""

    words: dict[int, dict[int, int]] = field(default_factory=dict)
    counters: dict[str, int] = field(default_factory=dict)

    def _count(self, name: str) -> None:
        self.counters[name] = self.counters.get(name, 0) + 1

    def add(self, svid: int, words: Sequence[int], t_ref_gps_s: float) -> KeplerEphemeris | None:
        if len(words) != 8:
            self._count("galileo_bad_length")
            return None
        even, odd = parts_from_words([int(w) & 0xFFFFFFFF for w in words])
        r_even, r_odd = BitReader(even, PART_BITS), BitReader(odd, PART_BITS)
        if r_even.u(0, 1) != 0 or r_odd.u(0, 1) != 1:
            self._count("galileo_bad_even_odd")
            return None
        if page_crc(even, odd) != r_odd.u(*ODD_CRC):
            self._count("galileo_bad_crc")
            return None
        if r_even.u(1, 1) or r_odd.u(1, 1):
            self._count("galileo_alert_page")
            return None
        word = word_from_parts(even, odd)
        wtype = BitReader(word, WORD_BITS).raw(WORD_TYPE)
        if not 1 <= wtype <= 5:
            self._count("galileo_other_word")  # spare/time (0), GST-UTC (6), almanacs, dummy (63)...
            return None
        got = self.words.setdefault(svid, {})
        got[wtype] = word
        if wtype <= 4:  # a new issue of data replaces the words of another one
            iod = BitReader(word, WORD_BITS).raw(IODNAV)
            stale = [k for k in range(1, 5) if k in got and BitReader(got[k], WORD_BITS).raw(IODNAV) != iod]
            if stale:
                self._count("galileo_iod_mismatch")
                for k in stale:
                    del got[k]
        if not all(k in got for k in range(1, 6)):
            return None
        eph = decode_ephemeris(svid, [got[k] for k in range(1, 6)], t_ref_gps_s)
        got.clear()  # the next set waits for its own word 5 (health and group delay as sent with it)
        self._count("galileo_ephemerides" if eph is not None else "galileo_svid_mismatch")
        return eph


def decode_ephemeris(svid: int, words: Sequence[int], t_ref_gps_s: float) -> KeplerEphemeris | None:
    """Word types 1-5 (one IODnav in 1-4) -> ephemeris; None when word 4's SVID is not ``svid``."""
    r = [BitReader(w, WORD_BITS) for w in words]
    if r[3].raw(SVID) != svid:
        return None
    v: dict[str, float] = {}
    for k in range(1, 5):
        v.update(get_all(r[k - 1], EPHEMERIS_WORDS[k]))
    w5 = r[4]
    toe_sow, toc_sow = v.pop("toe_sow_s"), v.pop("toc_sow_s")
    toe = math.floor(t_ref_gps_s / WEEK_S) * WEEK_S + toe_sow if math.isfinite(t_ref_gps_s) else toe_sow
    toe += WEEK_S * round((t_ref_gps_s - toe) / WEEK_S) if math.isfinite(t_ref_gps_s) else 0.0
    toc = toe - toe_sow + toc_sow
    toc += WEEK_S * round((toe - toc) / WEEK_S)
    health = (w5.raw(E1B_DVS) | w5.raw(E1B_HS) << 1 | w5.raw(E5B_DVS) << 6 | w5.raw(E5B_HS) << 7)
    return KeplerEphemeris(
        system=int(System.GALILEO), prn=int(svid), toe_gps_s=toe, toc_gps_s=toc, toe_sow_s=toe_sow,
        tgd_s=w5.get(BGD_E1E5B), iode=r[0].raw(IODNAV), health=health,
        accuracy_m=sisa_m(r[2].raw(SISA)), **v)
