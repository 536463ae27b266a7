"""Galileo I/NAV and BeiDou D1 navigation data of a broadcast ephemeris, as a u-blox receiver reports
them in RXM-SFRBX (pure: words out). The inverse of ``companion.gnss.inav`` / ``companion.gnss.bdsnav``,
written from their field tables (one statement of each layout); values must sit on the message's
resolution (``simvehicle.constellation`` quantises to it), a value out of a field's range raises.

* Galileo: the 128-bit word of type 0-5 (0: the time word, 1-4: the ephemeris, 5: BGDs, health, WN,
  TOW), split into the even (112 bits) and odd (16 bits) page parts with the CRC-24Q of the pair: eight
  SFRBX words. Not sent: the ionosphere (ai0-2 zero), almanacs, GST-UTC, SAR, OSNMA (zero bits).
* BeiDou D1: subframes 1-5 (4-5 carry only their header: no almanac) with every BCH(15,11) parity
  bit: ten SFRBX words of 30 bits. Not sent: the Klobuchar set (zero), TGD2 (zero). D2 (GEO):
  subframe 1's ten pages (``d2_pages``; the simulated sky has no GEO satellite, the tests use it).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from companion.gnss import bdsnav, inav, lnav
from companion.gnss.ephemeris import KeplerEphemeris
from companion.gnss.navbits import BitWriter, set_all, to_words
from companion.gnss.timescale import gps_to_bdt_s

WEEK_S = 604800.0
GST_WEEK_OFFSET = 1024  # GST week 0 = GPS week 1024


def _fields(eph: KeplerEphemeris, names: Iterable[str]) -> dict[str, float]:
    return {n: float(getattr(eph, n)) for n in names if hasattr(eph, n)}


def inav_word(eph: KeplerEphemeris, word_type: int, t_gps_s: float) -> int:
    """I/NAV word ``word_type`` (0-5) of ``eph`` sent at GST ``t_gps_s`` (word 0 and 5 carry WN/TOW)."""
    w = BitWriter(inav.WORD_BITS)
    w.set_raw(inav.WORD_TYPE, word_type)
    week = int(t_gps_s // WEEK_S)
    tow = int(round(t_gps_s - week * WEEK_S)) % int(WEEK_S)
    if 1 <= word_type <= 4:
        w.set_raw(inav.IODNAV, eph.iode)
        values = _fields(eph, inav.EPHEMERIS_WORDS[word_type])
        if word_type == 4:
            values["toc_sow_s"] = eph.toc_gps_s % WEEK_S
            w.set_raw(inav.SVID, eph.prn)
        if word_type == 3:
            w.set_raw(inav.SISA, inav.sisa_index(eph.accuracy_m))
        set_all(w, inav.EPHEMERIS_WORDS[word_type], values)
    elif word_type == 5:
        w.set(inav.BGD_E1E5B, eph.tgd_s)
        for f, bits in ((inav.E1B_DVS, 0), (inav.E1B_HS, 1), (inav.E5B_DVS, 6), (inav.E5B_HS, 7)):
            w.set_raw(f, (eph.health >> bits) & ((1 << f.width) - 1))
    if word_type in (0, 5):
        if word_type == 0:
            w.put(6, 2, 0b10)  # "time field valid"
            w.put(96, 12, (week - GST_WEEK_OFFSET) % 4096)
            w.put(108, 20, tow)
        else:
            w.set_raw(inav.WN, (week - GST_WEEK_OFFSET) % 4096)
            w.set_raw(inav.TOW, tow)
    return w.v


def inav_sfrbx_words(word: int, alert: bool = False) -> list[int]:
    """The eight SFRBX words of the page pair carrying ``word`` (CRC-24Q included)."""
    even = BitWriter(inav.PART_BITS)
    odd = BitWriter(inav.PART_BITS)
    even.put(0, 1, 0)
    even.put(1, 1, int(alert))
    even.put(2, 112, word >> 16)
    odd.put(0, 1, 1)
    odd.put(1, 1, int(alert))
    odd.put(2, 16, word & 0xFFFF)
    odd.put(*inav.ODD_CRC, inav.page_crc(even.v, odd.v))
    return to_words(even.v << 8, 4, 32) + to_words(odd.v << 8, 4, 32)


def d1_subframe(eph: KeplerEphemeris, subframe: int, t_bdt_s: float) -> list[int]:
    """D1 subframe ``subframe`` (1-5) of ``eph`` starting at BDT ``t_bdt_s`` (seconds since the BDT
    epoch): ten 30-bit words with their parity."""
    w = BitWriter(bdsnav.SUBFRAME_BITS)
    week = int(math.floor(t_bdt_s / WEEK_S))
    w.put(0, 11, bdsnav.PREAMBLE)
    w.set_raw(bdsnav.FRAID, subframe)
    w.set_raw(bdsnav.SOW, int(round(t_bdt_s - week * WEEK_S)) % int(WEEK_S))
    toe_sow = int(round(eph.toe_sow_s / 8.0))
    if subframe == 1:
        bdt_toc = gps_to_bdt_s(eph.toc_gps_s)
        w.set_raw(bdsnav.SATH1, eph.health & 1)
        w.set_raw(bdsnav.AODC, eph.iode)
        w.set_raw(bdsnav.URAI, lnav.ura_index(eph.accuracy_m))
        w.set_raw(bdsnav.WN, week % 8192)
        w.set(bdsnav.TOC, bdt_toc % WEEK_S)
        w.set(bdsnav.TGD1, eph.tgd_s)
        w.set_raw(bdsnav.AODE, eph.iode)
        set_all(w, bdsnav.CLOCK, _fields(eph, bdsnav.CLOCK))
    elif subframe == 2:
        set_all(w, bdsnav.ORBIT_2, _fields(eph, bdsnav.ORBIT_2))
        w.set_raw(bdsnav.TOE_MSB, toe_sow >> 15)
    elif subframe == 3:
        set_all(w, bdsnav.ORBIT_3, _fields(eph, bdsnav.ORBIT_3))
        w.set_raw(bdsnav.TOE_LSB, toe_sow & 0x7FFF)
    return [bdsnav.with_parity(k, x) for k, x in enumerate(to_words(w.v, 10, 30))]


def d2_pages(eph: KeplerEphemeris, t_bdt_s: float) -> list[list[int]]:
    """The ten pages of D2 subframe 1 (a GEO satellite's ephemeris; page 2, the ionosphere grid, left
    empty) of a cycle starting at BDT ``t_bdt_s``, 3 s apart: ten lists of ten 30-bit words."""
    whole = BitWriter(bdsnav.SUBFRAME_BITS * bdsnav.D2_PAGES)
    set_all(whole, bdsnav.D2_FIELDS, _fields(eph, bdsnav.D2_FIELDS))
    whole.set(bdsnav.D2_TOE, eph.toe_sow_s)
    whole.set_raw(bdsnav.D2_AODE, eph.iode)
    week = int(math.floor(t_bdt_s / WEEK_S))
    out = []
    for page in range(1, bdsnav.D2_PAGES + 1):
        shift = bdsnav.SUBFRAME_BITS * (bdsnav.D2_PAGES - page)
        w = BitWriter(bdsnav.SUBFRAME_BITS)
        w.v = (whole.v >> shift) & ((1 << bdsnav.SUBFRAME_BITS) - 1)
        w.put(0, 11, bdsnav.PREAMBLE)
        w.set_raw(bdsnav.FRAID, 1)
        w.set_raw(bdsnav.SOW, int(round(t_bdt_s + 3.0 * (page - 1) - week * WEEK_S)) % int(WEEK_S))
        w.set_raw(bdsnav.PNUM, page)
        if page == 1:
            w.set_raw(bdsnav.D2_SATH1, eph.health & 1)
            w.set_raw(bdsnav.D2_AODC, eph.iode)
            w.set_raw(bdsnav.D2_URAI, lnav.ura_index(eph.accuracy_m))
            w.set_raw(bdsnav.D2_WN, week % 8192)
            w.set(bdsnav.D2_TOC, gps_to_bdt_s(eph.toc_gps_s) % WEEK_S)
            w.set(bdsnav.D2_TGD1, eph.tgd_s)
        out.append([bdsnav.with_parity(k, x) for k, x in enumerate(to_words(w.v, 10, 30))])
    return out
