"""Galileo I/NAV and BeiDou D1 from u-blox RXM-SFRBX: real broadcast words decoded to the values an
independent decoder publishes for them, the simulator's encoder and the decoders round-tripping every
field at its ICD resolution, CRC-24Q / BCH(15,11) catching every single bit flip, hostile words counted
and never raised on, and a simulated GPS+Galileo+BeiDou UBX log solved by ``beliefnav gnss spp`` with
the Galileo and BeiDou satellites in it."""

import dataclasses
import math

import numpy as np
import pytest

from companion.gnss import bdsnav, inav, lnav
from companion.gnss.bdsnav import BeidouDecoder
from companion.gnss.ephemeris import EphemerisStore, KeplerEphemeris
from companion.gnss.geometry import geodetic_to_ecef
from companion.gnss.inav import GalileoDecoder
from companion.gnss.navbits import from_words
from companion.gnss.systems import System
from companion.gnss.timescale import bdt_to_gps_s, gps_to_bdt_s
from simvehicle.constellation import constellation
from simvehicle.navmsg import d1_subframe, d2_pages, inav_sfrbx_words, inav_word

# Real broadcast data, for a cross-check against decoders written by others:
# Galileo E01, GST week 1014, I/NAV word types 1-5 (128-bit words) as GNSSTk's test data holds them
# (SGL-UT/gnsstk core/tests/NewNav/GalINavTestDataDef.hpp; LGPL), with the values GNSSTk's
# PNBGalINavDataFactory decodes from them (PNBGalINavDataFactory_T.cpp)
GAL_E01_WORDS = (
    (0x045E86B2, 0x14606028, 0x0039B8BE, 0xA813EC77),
    (0x085E78BB, 0x0E292854, 0x403C05B7, 0x23FFF7FD),
    (0x0C5EFFC8, 0x1B1BAB09, 0xAB19670C, 0x0B0C496B),
    (0x105E07FF, 0xE3FFFA1A, 0xCFEE8486, 0xFFFDC601),
    (0x145B82A0, 0x0581F67D, 0x401FB3F4, 0x8CAAAAAA),
)
GAL_E01_T_GPS_S = (1014 + 1024) * 604800.0 + 518425.0
GAL_E01_GNSSTK = {
    "cuc_rad": 4.610046744347e-06, "cus_rad": 1.211278140545e-05, "crc_m": 96.34375, "crs_m": 98.28125,
    "cis_rad": -3.725290298462e-09, "cic_rad": -1.490116119385e-08, "m0_rad": -3.0165642165792534435,
    "delta_n_rad_s": 2.529748231311e-09, "e": 1.100952504203e-04, "sqrt_a_m05": 5.4406226139068603516e03,
    "omega0_rad": 2.9631768162768818975, "i0_rad": 9.8982515960810546485e-01,
    "omega_rad": 1.4027684908239376749e-01, "omega_dot_rad_s": -5.110570018612e-09,
    "idot_rad_s": -1.832219176426e-10, "af0_s": -5.335179739632e-04, "af1_s_s": -8.100187187665e-12,
    "af2_s_s2": 0.0, "tgd_s": -22 * 2.0**-32,  # BGD(E1,E5b): GNSSTk prints -5.122274e-09
}
# BeiDou C10, BDT week 642 (GPS 1998): D1 subframes 1-3 as ten 30-bit words each (de-interleaved,
# parity included) from Swift Navigation's BeiDou decoder tests (nav_msg_bds tests), with their
# reference ephemeris (toe 201600 s BDT, TGD1 5.6 ns)
BDS_C10_SUBFRAMES = (
    (0x38901313, 0x12380030, 0x05046242, 0x1C0380CC, 0x1E0A1484,
     0x3A0B8FFE, 0x0EF13020, 0x20007494, 0x08647F83, 0x3053E192),
    (0x38902311, 0x12502F78, 0x2AF7A35A, 0x0C5842F1, 0x3C440AE4,
     0x0CC3A9FE, 0x09FE5E27, 0x2917F8A6, 0x1D6CAE2C, 0x342E5C51),
    (0x3890331E, 0x126B13E2, 0x204B051D, 0x0D487F3A, 0x3E8FFF4F,
     0x1155FEA1, 0x16DA91F5, 0x28A22CF0, 0x374C7FF3, 0x02C09A96),
)
BDS_C10_SWIFT = {
    "crc_m": -3.47640625e02, "crs_m": -1.20656250e02, "cuc_rad": -3.98792326450e-06,
    "cus_rad": 1.90609134734e-05, "cic_rad": -2.18860805035e-08, "cis_rad": -3.92086803913e-07,
    "delta_n_rad_s": 1.08933108930e-09, "m0_rad": -1.43540489556, "e": 4.98019636143e-03,
    "sqrt_a_m05": 6.49363065910e03, "omega0_rad": 1.69518318499, "omega_dot_rad_s": -2.13366030409e-09,
    "omega_rad": -2.75182959435, "i0_rad": 9.20638105072e-01, "idot_rad_s": -9.93255658799e-10,
    "af0_s": -1.81104638614e-04, "af1_s_s": -2.85078627371e-11, "af2_s_s2": 0.0, "tgd_s": 5.6e-09,
}

# BeiDou C01 (GEO), BDT week 810: D2 subframe 1 pages 1-10 (GNSSTk's D2NavTestDataDef.hpp), with the
# values GNSSTk's PNBBDSD2NavDataFactory decodes from them
BDS_C01_D2_PAGES = (
 (0x38901541,0x18004027,0x00654A7C,0x2303C840,0x39B015EA,0x1555554B,0x1555554B,0x1555554B,0x1555554B,0x1555554B),
 (0x38901541,0x180C8114,0x304FB0CA,0x1CDC2F71,0x380755B6,0x1555554B,0x1555554B,0x1555554B,0x1555554B,0x1555554B),
 (0x38901541,0x1818C079,0x00000000,0x000DC13C,0x3C88153A,0x1555554B,0x1555554B,0x1555554B,0x1555554B,0x1555554B),
 (0x38901541,0x18250AEB,0x0E4C00E9,0x01F8D7D5,0x373C55E4,0x1555554B,0x1555554B,0x1555554B,0x1555554B,0x1555554B),
 (0x38901541,0x18317E86,0x31E9F0F9,0x047BD7C7,0x3C015552,0x1555554B,0x1555554B,0x1555554B,0x1555554B,0x1555554B),
 (0x38901541,0x183D90BD,0x35CA72D3,0x2EB5040A,0x3FFE55F9,0x1555554B,0x1555554B,0x1555554B,0x1555554B,0x1555554B),
 (0x38901541,0x1849CEA7,0x3002B543,0x14600143,0x304F55C6,0x1555554B,0x1555554B,0x1555554B,0x1555554B,0x1555554B),
 (0x38901541,0x185621FD,0x301EAF12,0x3C0CB863,0x002515CC,0x1555554B,0x1555554B,0x1555554B,0x1555554B,0x1555554B),
 (0x38901541,0x18626153,0x005173D2,0x0146E114,0x238B552F,0x1555554B,0x1555554B,0x1555554B,0x1555554B,0x1555554B),
 (0x38901541,0x186E8E6B,0x08A8AA59,0x2AAAAAB4,0x2AAAAAB4,0x2AAAAAB4,0x2AAAAAB4,0x2AAAAAB4,0x2AAAAAB4,0x2AAAAAB4),
)
BDS_C01_GNSSTK = {
    "cus_rad": -7.9278834164142608643e-06, "cuc_rad": -1.6712117940187454224e-05, "crc_m": 2.45484375e02,
    "crs_m": -5.05640625e02, "cic_rad": -2.10944563e-07, "cis_rad": 8.05594027e-08,
    "m0_rad": -1.916523214107468176, "delta_n_rad_s": -6.54670127e-10, "e": 6.1676383484154939651e-04,
    "sqrt_a_m05": math.sqrt(4.2164428143935076892e07), "omega0_rad": -3.1259749468667630268,
    "i0_rad": 8.6141192515002310004e-02, "omega_rad": 1.3510960489050376498,
    "omega_dot_rad_s": 1.69721355e-09, "idot_rad_s": 3.95730769e-10, "af0_s": -2.7373037301003932953e-04,
    "af1_s_s": 3.71924713e-11, "af2_s_s2": 0.0,
}


def _word128(four: tuple[int, ...]) -> int:
    return int.from_bytes(b"".join(w.to_bytes(4, "big") for w in four), "big")


def test_real_galileo_words_decode_to_the_values_gnsstk_publishes():
    dec = GalileoDecoder()
    got = [dec.add(1, inav_sfrbx_words(_word128(w)), GAL_E01_T_GPS_S) for w in GAL_E01_WORDS]
    assert got[:4] == [None] * 4 and dec.counters == {"galileo_ephemerides": 1}
    eph = got[4]
    for name, value in GAL_E01_GNSSTK.items():
        assert getattr(eph, name) == pytest.approx(value, rel=1e-9, abs=1e-21), name
    assert (eph.iode, eph.health, eph.prn, eph.system) == (94, 0, 1, System.GALILEO)
    assert eph.accuracy_m == pytest.approx(inav.sisa_m(107)) == pytest.approx(3.12)  # SISA index 107
    assert eph.toe_gps_s == eph.toc_gps_s == (1014 + 1024) * 604800.0 + 517200.0  # toe in GST (= GPS)
    # a word with another IODnav is a cut-over, not part of this set
    stale = _word128(GAL_E01_WORDS[1]) ^ (1 << (128 - 16))  # IODnav 94 -> 95 in word type 2
    for w in (GAL_E01_WORDS[0], None, GAL_E01_WORDS[2], GAL_E01_WORDS[3], GAL_E01_WORDS[4]):
        assert dec.add(1, inav_sfrbx_words(stale if w is None else _word128(w)), GAL_E01_T_GPS_S) is None
    assert dec.counters["galileo_iod_mismatch"] >= 1 and dec.counters["galileo_ephemerides"] == 1
    # and word type 4 names its satellite: E01's words on another SVID are refused, counted
    other = GalileoDecoder()
    for w in GAL_E01_WORDS:
        assert other.add(2, inav_sfrbx_words(_word128(w)), GAL_E01_T_GPS_S) is None
    assert other.counters == {"galileo_svid_mismatch": 1}


def test_real_beidou_subframes_pass_bch_and_decode_to_swift_navigations_values():
    dec = BeidouDecoder()
    got = [dec.add(10, sf) for sf in BDS_C10_SUBFRAMES]
    assert got[:2] == [None, None] and dec.counters == {"beidou_ephemerides": 1}
    eph = got[2]
    for name, value in BDS_C10_SWIFT.items():
        assert getattr(eph, name) == pytest.approx(value, rel=1e-9, abs=1e-21), name
    assert eph.toe_gps_s == bdt_to_gps_s(642 * 604800.0 + 201600.0) == 1998 * 604800.0 + 201614.0
    assert (eph.toe_sow_s, eph.health, eph.accuracy_m, eph.iode) == (201600.0, 0, 2.4, 1)
    # the encoder writes subframes 2 and 3 back bit for bit, parity included (subframe 1 also carries
    # AODC, TGD2 and the BeiDou Klobuchar set, which it leaves at zero): the layout is the ICD's, not
    # merely one the two sides agree on
    t_bdt = 642 * 604800.0 + 201870.0  # subframe 1's SOW
    for k in (1, 2):
        assert d1_subframe(eph, k + 1, t_bdt + 6.0 * k) == list(BDS_C10_SUBFRAMES[k])


def test_real_beidou_geo_pages_decode_to_the_values_gnsstk_publishes():
    """The D2 message of a GEO satellite: subframe 1's pages 1, 3-10 (page 2 is the ionosphere grid)."""
    dec = BeidouDecoder()
    got = [dec.add(1, page) for page in BDS_C01_D2_PAGES]
    assert got[:9] == [None] * 9 and dec.counters == {"beidou_d2_other": 1, "beidou_ephemerides": 1}
    eph = got[9]
    for name, value in BDS_C01_GNSSTK.items():
        assert getattr(eph, name) == pytest.approx(value, rel=1e-8, abs=1e-21), name
    assert eph.toe_gps_s == bdt_to_gps_s(810 * 604800.0 + 345600.0) and eph.toe_sow_s == 345600.0
    # written back: words 1-4 of pages 3-9, parity included, bit for bit
    mine = d2_pages(eph, 810 * 604800.0 + 345600.0)
    assert BeidouDecoder().add(1, mine[0]) is None
    for p in range(2, 9):
        bits = from_words(mine[p], 30) ^ from_words(BDS_C01_D2_PAGES[p], 30)
        assert bits >> 180 == 0, p + 1  # words 1-4 equal (word 5 ends in reserved bits, then parity)
    # the same pages on a MEO/IGSO PRN are not D1 subframes 1-3
    assert [BeidouDecoder().add(30, page) for page in BDS_C01_D2_PAGES] == [None] * 10


def _random_ephemeris(rng: np.random.Generator, system: System, prn: int) -> KeplerEphemeris:
    """An ephemeris with every field a random value on its message's grid and within its range."""
    if system == System.GALILEO:
        tables = [inav.EPHEMERIS_WORDS[k] for k in (1, 2, 3, 4)]
    elif prn <= 5:  # a BeiDou GEO: D2
        tables = [bdsnav.D2_FIELDS]
    else:
        tables = [bdsnav.CLOCK, bdsnav.ORBIT_2, bdsnav.ORBIT_3]
    v: dict[str, float] = {}
    for table in tables:
        for name, f in table.items():
            w = f.width
            lo, hi = (-(1 << (w - 1)), (1 << (w - 1))) if f.signed else (0, 1 << w)
            v[name] = int(rng.integers(lo, hi)) * f.lsb
    v.pop("toc_sow_s", None)
    v.pop("toe_sow_s", None)
    toe_sow = float(rng.integers(0, 604800 // 120) * 120)  # on both grids (I/NAV 60 s, D1 8 s)
    week = 2300 + int(rng.integers(0, 50))
    if system == System.GALILEO:
        toe = week * 604800.0 + toe_sow
        hs = rng.integers(0, 4, 2)
        health = int(rng.integers(0, 2)) | int(hs[0]) << 1 | int(rng.integers(0, 2)) << 6 | int(hs[1]) << 7
        tgd, iode = int(rng.integers(-512, 512)) * 2.0**-32, int(rng.integers(0, 1024))
        acc = inav.sisa_m(int(rng.integers(0, 126)))
    else:
        toe = bdt_to_gps_s((week - 1356) * 604800.0 + toe_sow)
        tgd, iode = int(rng.integers(-512, 512)) * 1e-10, int(rng.integers(0, 32))
        health = int(rng.integers(0, 2))
        acc = lnav.ura_m(int(rng.integers(0, 16)))
    return KeplerEphemeris(system=int(system), prn=prn, toe_gps_s=toe, toc_gps_s=toe, toe_sow_s=toe_sow,
                           tgd_s=tgd, iode=iode, health=health, accuracy_m=acc, **v)


def _gal_round_trip(eph: KeplerEphemeris, t_gps_s: float, dec: GalileoDecoder) -> KeplerEphemeris | None:
    out = None
    for k in (2, 4, 1, 3, 5):  # the order of the nominal E1-B subframe
        out = dec.add(eph.prn, inav_sfrbx_words(inav_word(eph, k, t_gps_s)), t_gps_s) or out
    return out


def _bds_round_trip(eph: KeplerEphemeris, t_gps_s: float, dec: BeidouDecoder) -> KeplerEphemeris | None:
    t_bdt = math.floor(gps_to_bdt_s(t_gps_s) / 30.0) * 30.0  # a frame start
    out = None
    if eph.prn <= 5:
        for page in d2_pages(eph, t_bdt):
            out = dec.add(eph.prn, page) or out
        return out
    for k in (1, 2, 3, 4, 5):
        out = dec.add(eph.prn, d1_subframe(eph, k, t_bdt + 6.0 * (k - 1))) or out
    return out


def test_every_field_round_trips_at_its_icd_resolution():
    """Random values on each field's grid over its whole range (the harmonics, clock terms and group
    delays the nominal sky leaves at zero included), and the simulated sky's Galileo and BeiDou
    ephemerides: encoded as SFRBX words and decoded, each comes back exactly, and so does every
    satellite position."""
    rng = np.random.default_rng(3)
    gal, bds = GalileoDecoder(), BeidouDecoder()
    pairs = []
    for i in range(60):
        for system, rt, dec in ((System.GALILEO, _gal_round_trip, gal),
                                (System.BEIDOU, _bds_round_trip, bds)):
            prn = int(rng.integers(1, 37))
            eph = _random_ephemeris(rng, system, prn)
            t = eph.toe_gps_s + float(rng.uniform(-7000.0, 7000.0))
            got = rt(eph, t, dec)
            assert got == eph, (system, i)
    kep, _ = constellation(1.4e9, 1.4e9 + 7200.0, (System.GALILEO, System.BEIDOU))
    for eph in kep:
        rt, dec = (_gal_round_trip, gal) if eph.system == System.GALILEO else (_bds_round_trip, bds)
        got = rt(eph, eph.toe_gps_s + 600.0, dec)
        assert got == eph
        pairs.append((eph, got))
    assert len(pairs) == len(kep) >= 2 * 2 * 24
    assert gal.counters["galileo_ephemerides"] == bds.counters["beidou_ephemerides"]
    a, b = (EphemerisStore([p[j] for p in pairs]) for j in (0, 1))
    sysv = np.array([p[0].system for p in pairs])
    prn = np.array([p[0].prn for p in pairs])
    t = np.array([p[0].toe_gps_s + 3000.0 for p in pairs])
    sa, sb = a.states(sysv, prn, t), b.states(sysv, prn, t)
    assert sa.valid.all() and np.abs(sa.pos_ecef_m - sb.pos_ecef_m).max() < 1e-3
    assert np.abs(sa.clock_s - sb.clock_s).max() < 1e-12
    # a value off its field's range is refused by the encoder, not wrapped
    with pytest.raises(ValueError, match="does not fit"):
        inav_word(dataclasses.replace(kep[0], af2_s_s2=1e-15), 4, kep[0].toe_gps_s)
    bds0 = next(e for e in kep if e.system == System.BEIDOU)
    with pytest.raises(ValueError, match="does not fit"):
        d1_subframe(dataclasses.replace(bds0, iode=40), 1, gps_to_bdt_s(bds0.toe_gps_s))


def test_every_single_bit_flip_is_caught_and_counted():
    """CRC-24Q over the I/NAV page pair; BCH(15,11) over each D1 code word: a flip of any protected bit
    is refused and counted (the bits outside the checks: I/NAV tails, padding and reserved 2, D1's
    preamble and reserved bits, are left out)."""
    eph_g = _random_ephemeris(np.random.default_rng(1), System.GALILEO, 11)
    words = inav_sfrbx_words(inav_word(eph_g, 1, eph_g.toe_gps_s))
    protected = [p for p in range(114)] + [128 + p for p in range(106)]  # even 0-113, odd 0-105
    dec = GalileoDecoder()
    for p in protected:
        w = list(words)
        w[p // 32] ^= 1 << (31 - p % 32)
        assert dec.add(11, w, eph_g.toe_gps_s) is None
    assert dec.counters["galileo_bad_crc"] + dec.counters["galileo_bad_even_odd"] == len(protected)
    assert dec.counters["galileo_bad_even_odd"] == 2 and set(dec.counters) == {"galileo_bad_crc",
                                                                               "galileo_bad_even_odd"}
    eph_b = _random_ephemeris(np.random.default_rng(2), System.BEIDOU, 21)
    sf = d1_subframe(eph_b, 2, gps_to_bdt_s(eph_b.toe_gps_s))
    assert all(bdsnav.word_parity_ok(k, x) for k, x in enumerate(sf))
    dec_b = BeidouDecoder()
    n = 0
    for k in range(10):
        for bit in range(30 if k else 15):  # word 1: the last 15 bits are one code word
            w = list(sf)
            w[k] ^= 1 << bit
            assert dec_b.add(21, w) is None
            n += 1
    assert dec_b.counters == {"beidou_bad_parity": n} and n == 285
    for bit in range(19, 30):  # word 1's first 11 bits (the preamble) sit outside the code words
        w = list(sf)
        w[0] ^= 1 << bit
        assert dec_b.add(21, w) is None
    assert dec_b.counters["beidou_bad_preamble"] == 11


def test_hostile_words_are_counted_never_raised_and_anything_decoded_is_finite():
    rng = np.random.default_rng(11)
    gal, bds = GalileoDecoder(), BeidouDecoder()
    decoded = []
    for i in range(3000):
        t = float(rng.choice([0.0, 1.4e9, 1e12, -1e9, math.nan]))
        n = 8 if i % 10 else int(rng.integers(0, 12))
        words = [int(x) for x in rng.integers(0, 2**32, n, dtype=np.uint64)]
        if n == 8 and i % 2:  # a valid page pair around random content: word types 0-7 mostly
            word = int.from_bytes(rng.bytes(16), "big")
            word = (word & ~(0x3F << 122)) | (int(rng.integers(0, 8)) << 122)
            words = inav_sfrbx_words(word, alert=bool(i % 7 == 0))
        got = gal.add(int(rng.integers(0, 64)), words, t)
        decoded += [got] if got is not None else []
        m = 10 if i % 10 else int(rng.integers(0, 14))
        words = [int(x) for x in rng.integers(0, 2**32, m, dtype=np.uint64)]
        if m == 10 and i % 2:  # valid parity and preamble around random content: subframes 1-5 mostly
            v = [int(x) & 0x3FFFFFFF for x in words]
            v[0] = (bdsnav.PREAMBLE << 19) | (int(rng.integers(0, 8)) << 12) | (v[0] & 0xFFF)
            words = [bdsnav.with_parity(k, x) for k, x in enumerate(v)]
        got = bds.add(int(rng.choice([1, 6, 19, 30, 45, 60, 255])), words)
        decoded += [got] if got is not None else []
    for key in ("galileo_bad_length", "galileo_bad_crc", "galileo_alert_page", "galileo_other_word",
                "galileo_bad_even_odd"):
        assert gal.counters.get(key, 0) > 0, key
    for key in ("beidou_bad_length", "beidou_bad_parity", "beidou_other_subframe", "beidou_d2_other",
                "beidou_inconsistent"):
        assert bds.counters.get(key, 0) > 0, key
    fields = [f.name for f in dataclasses.fields(KeplerEphemeris) if f.name != "accuracy_m"]
    assert all(np.isfinite([getattr(e, f) for f in fields]).all() for e in decoded)


@pytest.fixture(scope="module")
def multi_flight(tmp_path_factory):
    """40 s of the canyon scenario's receiver with GPS, Galileo and BeiDou (an opt-in: the scenario's
    default is GPS + GLONASS), as a UBX log."""
    from companion.mission import load_mission
    from simvehicle import SimVehicle
    from simvehicle.config import sim_config_for
    from simvehicle.ubx import UbxEncoder

    mission = load_mission("default", "canyon")
    cfg = sim_config_for(mission)
    receiver = dataclasses.replace(cfg.receiver, systems=("GPS", "GALILEO", "BEIDOU"))
    cfg = dataclasses.replace(cfg, receiver=receiver)
    sim = SimVehicle(mission, 4, 0, cfg)
    enc = UbxEncoder(sim.gnss.store)
    raws, frames, ticks = [], [], []
    while sim.t_us < 40e6:
        out = sim.advance(None, None)
        for raw in out.gnss_raw:
            raws.append(raw)
            frames += enc.epoch_frames(raw)
        ticks += [(t, out.truth_at(i).p_ned_m) for i, t in enumerate(out.tick_us)]
    path = tmp_path_factory.mktemp("multi") / "receiver.ubx"
    path.write_bytes(b"".join(frames))
    t_us = np.array([t for t, _ in ticks], dtype=float)
    p_ned = np.array([p for _, p in ticks])
    truth = {}  # receiver time tag -> the true antenna position (ECEF) at the measurement
    for raw in raws:
        p = np.array([np.interp(raw.t_us, t_us, p_ned[:, j]) for j in range(3)])
        lat, lon, alt = sim.mission.frame.to_geodetic(p)
        truth[raw.epoch.t_gps_s] = np.asarray(geodetic_to_ecef(math.radians(lat), math.radians(lon), alt))
    return sim, raws, path, truth


def test_a_gps_galileo_beidou_ubx_log_is_solved_with_its_galileo_and_beidou_satellites(multi_flight):
    sim, raws, path, truth = multi_flight
    # what ``beliefnav gnss spp receiver.ubx`` does (its reader and its evaluation, in-process)
    from companion.gnss.spp import SppConfig
    from gcs_tools.gnss.cli import evaluate
    from gcs_tools.gnss.sources import load_input

    data = load_input(path, [], None, None)
    summary, series, _ = evaluate(data, SppConfig())
    assert summary["solutions"] == summary["epochs"] == len(raws) and series.ok.all()
    counts = summary["rejected"]
    assert counts["galileo_ephemerides"] > 0 and counts["beidou_ephemerides"] > 0
    assert not {"galileo_bad_crc", "beidou_bad_parity", "beidou_inconsistent"} & set(counts)
    ephs = data.store.kepler
    assert all(e in sim.gnss.store.kepler for e in ephs)  # exactly the simulator's broadcast sets
    for system in (System.GALILEO, System.BEIDOU):
        assert len({e.prn for e in ephs if e.system == system}) >= 4
    pairs = list(zip(data.epochs, series.solutions, strict=True))
    used = {s_: np.array([int(((ep.system == s_) & sol.used).sum()) for ep, sol in pairs])
            for s_ in (System.GPS, System.GALILEO, System.BEIDOU)}
    assert np.median(used[System.GALILEO]) >= 3 and np.median(used[System.BEIDOU]) >= 3
    err = np.array([np.linalg.norm(sol.p_ecef_m - truth[ep.t_gps_s]) for ep, sol in pairs])
    # the receiver's own fixes (the same solver, every ephemeris it flies) set the expectation
    own = np.array([np.linalg.norm(r.solution.p_ecef_m - truth[r.epoch.t_gps_s]) for r in raws
                    if r.solution is not None])
    assert np.median(err) < min(np.median(own) + 0.5, 5.0)


def test_receiver_json_carries_the_accuracy_as_strict_json():
    """``receiver.json`` (the simulated receiver's sky for its consumers) stays strict JSON: an accuracy
    not given (NaN) is written as null and read back as NaN, "no prediction" (inf) as "inf" and read
    back as inf; a given one as itself."""
    import json

    from simvehicle.ubx_server import _kepler_json, store_from_info

    kep, _ = constellation(1.4e9, 1.4e9 + 3600.0, (System.GALILEO,))
    ephs = [dataclasses.replace(kep[0], accuracy_m=math.nan),
            dataclasses.replace(kep[1], accuracy_m=math.inf), kep[2]]
    assert kep[2].accuracy_m == inav.sisa_m(107)  # the simulated sky's: SISA index 107, 3.12 m
    text = json.dumps({"ephemerides": {"kepler": [_kepler_json(e) for e in ephs], "glonass": []}},
                      allow_nan=False)
    back = store_from_info(json.loads(text)).kepler
    assert [dataclasses.replace(e, accuracy_m=0.0) for e in back] == [
        dataclasses.replace(e, accuracy_m=0.0) for e in ephs]
    assert math.isnan(back[0].accuracy_m) and back[1].accuracy_m == math.inf and back[2].accuracy_m == 3.12
