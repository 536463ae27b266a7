"""RINEX 3 navigation records: the broadcast accuracy (GPS/BeiDou URA, Galileo SISA) and the choice
of Galileo records (I/NAV with the E5b,E1 clock for E1 pseudoranges; F/NAV counted, not mixed in),
on real records with their published values; and the same broadcast read through the UBX decoders
and through a RINEX file giving the same ``accuracy_m``, satellite positions and clocks."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from companion.errors import UserError
from companion.gnss import inav, lnav
from companion.gnss.bdsnav import BeidouDecoder
from companion.gnss.ephemeris import EphemerisStore, KeplerEphemeris
from companion.gnss.inav import GalileoDecoder
from companion.gnss.lnav import LnavDecoder
from companion.gnss.systems import System
from companion.gnss.timescale import gps_from_calendar, week_tow
from gcs_tools.gnss import rinex
from simvehicle.constellation import constellation
from simvehicle.navmsg import inav_sfrbx_words
from simvehicle.ubx import lnav_subframe
from tests.gnss_helpers_lnav import SUBFRAMES_PRN21
from tests.test_multignss_nav import (
    BDS_C10_SUBFRAMES,
    GAL_E01_T_GPS_S,
    GAL_E01_WORDS,
    _bds_round_trip,
    _gal_round_trip,
    _word128,
)

# Real records. GPS G01, 2017-11-17, a receiver's own file (LgsRinex, RINEX 3.02; georinex's test
# data demo_nav3.17n, MIT): SV accuracy written as the nominal 2.0 m of URA index 0.
GPS_G01 = """\
3.02                N: GNSS NAV DATA    G: GPS              RINEX VERSION / TYPE
    18    18  1929     7                                    LEAP SECONDS
                                                            END OF HEADER
G01 2017 11 17 00 00 00-1.082336530089D-05-2.387423592154D-12 0.000000000000D+00
     2.600000000000D+01 4.312500000000D+01 4.455542601534D-09 2.261013945883D+00
     2.192333340645D-06 7.114754174836D-03 7.407739758492D-06 5.153672552109D+03
     4.320000000000D+05-9.126961231232D-08 7.577775093435D-01-7.450580596924D-08
     9.691207199508D-01 2.407187500000D+02 6.318014759246D-01-7.981403982171D-09
     5.718095441587D-10 1.000000000000D+00 1.975000000000D+03 0.000000000000D+00
     2.000000000000D+00 0.000000000000D+00 5.587935447693D-09 2.600000000000D+01
     4.247400000000D+05
"""
# BeiDou C01 (GEO), 2014-05-10, from the DLR/TUM merged broadcast file (GNSSTk's test data
# test_input_rinex3_nav_BeiDou.14n, LGPL): SV accuracy 2.0 m, TGD1 14.2 ns, TGD2 −10.4 ns.
BDS_C01 = """\
     3.04           NAVIGATION DATA     M (Mixed)           RINEX VERSION / TYPE
                                                            END OF HEADER
C01 2014 05 10 00 00 00 2.969256602228e-04 2.196998138970e-11 0.000000000000e+00
     1.000000000000e+00 4.365468750000e+02 1.318269196918e-09-3.118148933476e+00
     1.447647809982e-05 2.822051756084e-04 8.092261850834e-06 6.493480609894e+03
     5.184000000000e+05-2.654269337654e-08 3.076630958509e+00-3.864988684654e-08
     1.103024081152e-01-2.506406250000e+02 2.587808789012e+00-3.039412318009e-10
     2.389385241772e-10 0.000000000000e+00 4.350000000000e+02 0.000000000000e+00
     2.000000000000e+00 0.000000000000e+00 1.420000000000e-08-1.040000000000e-08
     5.184000000000e+05 0.000000000000e+00
"""
# Galileo E24, 2020-05-15 00:00, IODnav 80, four records of one issue of data from the IGS merged
# broadcast file BRDC00IGS_R_20201360000_01D_MN.rnx (georinex's test data): data sources 258 (F/NAV
# E5a-I, clock E5a,E1), 513 (I/NAV E1-B, clock E5b,E1), 516 (I/NAV E5b-I), 517 (I/NAV E1-B + E5b-I);
# SISA 3.12 m; BGD E5a/E1 45.40 ns, BGD E5b/E1 50.99 ns (zero in the F/NAV record, which has no E5b).
# The last two records end their lines early (the writer left the trailing spare fields out).
_E24_ORBIT = """\
     8.000000000000E+01 3.037500000000E+01 2.826903466162E-09 1.111185876666E-01
     1.413747668266E-06 5.261546466500E-04 6.578862667084E-06 5.440599994659E+03
     4.320000000000E+05-3.725290298462E-08 9.568013010147E-01-1.490116119385E-08
     9.805210430486E-01 2.093750000000E+02 8.678592816169E-01-5.435583556730E-09
"""
GAL_E24 = f"""\
     3.04           NAVIGATION DATA     MIXED               RINEX VERSION / TYPE
    18    18  1929     7GPS                                 LEAP SECONDS
                                                            END OF HEADER
E24 2020 05 15 00 00 00 5.455514357891E-03-1.993782916543E-11 0.000000000000E+00
{_E24_ORBIT}\
    -2.946551307118E-10 2.580000000000E+02 2.105000000000E+03 0.000000000000E+00
     3.120000000000E+00 0.000000000000E+00 4.540197551250E-08 0.000000000000E+00
     4.327000000000E+05 0.000000000000E+00 0.000000000000E+00 0.000000000000E+00
E24 2020 05 15 00 00 00 5.455520295072E-03-1.993782916543E-11 0.000000000000E+00
{_E24_ORBIT}\
    -2.946551307118E-10 5.130000000000E+02 2.105000000000E+03 0.000000000000E+00
     3.120000000000E+00 0.000000000000E+00 4.540197551250E-08 5.098991096020E-08
     4.326550000000E+05 0.000000000000E+00 0.000000000000E+00 0.000000000000E+00
E24 2020 05 15 00 00 00 5.455520295070E-03-1.993782916540E-11 0.000000000000E+00
{_E24_ORBIT}\
    -2.946551307120E-10 5.160000000000E+02 2.105000000000E+03
     3.120000000000E+00 0.000000000000E+00 4.540197551250E-08 5.098991096020E-08
     4.326640000000E+05
E24 2020 05 15 00 00 00 5.455520295072E-03-1.993782916543E-11 0.000000000000E+00
{_E24_ORBIT}\
    -2.946551307118E-10 5.170000000000E+02 2.105000000000E+03
     3.120000000000E+00 0.000000000000E+00 4.540197551250E-08 5.098991096020E-08
     4.326650000000E+05
"""
E24_SOURCES = ("2.580000000000E+02", "5.130000000000E+02", "5.160000000000E+02", "5.170000000000E+02")


def _read(tmp_path: Path, text: str, name: str = "x.nav") -> rinex.RinexNav:
    p = tmp_path / name
    p.write_text(text)
    return rinex.read_nav(p)


def test_real_gps_and_beidou_records_give_the_broadcast_ura(tmp_path):
    """The nominal 2.0 m a writer puts for URA index 0 reads as that index's 2.4 m, the value the
    UBX decoders give for index 0; the other fields as the records state them."""
    (g,) = _read(tmp_path, GPS_G01, "g.nav").kepler
    assert (g.system, g.prn, g.iode, g.health) == (System.GPS, 1, 26, 0)
    assert g.accuracy_m == lnav.ura_m(0) == 2.4 and g.tgd_s == 5.587935447693e-09
    assert week_tow(g.toe_gps_s) == (1975, 432000.0)
    (c,) = _read(tmp_path, BDS_C01, "c.nav").kepler
    assert (c.system, c.prn, c.iode, c.health) == (System.BEIDOU, 1, 1, 0)
    assert c.accuracy_m == 2.4 and c.tgd_s == 1.42e-08  # TGD1: the B1I group delay


@pytest.mark.parametrize("n", range(16))
def test_every_ura_index_reads_back_from_its_nominal_and_its_bound(tmp_path, n):
    """RINEX 3.05 (GPS broadcast orbit 6): the nominal value is 2^(1+N/2) rounded to 0.1 m for N ≤ 6
    and 2^(N−2) above (8192 m: index 15, "no prediction"), what the writer puts; some writers put the
    interval's upper bound. Both give ``lnav.ura_m(N)``, the UBX decoder's value, for GPS, QZSS and
    BeiDou alike."""
    nominal = round(2.0 ** (1.0 + n / 2.0), 1) if n <= 6 else 2.0 ** (n - 2)
    for system in (System.GPS, System.QZSS, System.BEIDOU):
        assert rinex.broadcast_accuracy_m(system, nominal) == lnav.ura_m(n)
        assert rinex.broadcast_accuracy_m(system, lnav.ura_m(n)) == lnav.ura_m(n)
    (g,) = _read(tmp_path, GPS_G01).kepler
    rinex.write_nav(tmp_path / "w.nav", [dataclasses.replace(g, accuracy_m=lnav.ura_m(n))])
    sv_accuracy = (tmp_path / "w.nav").read_text().splitlines()[-2][4:23]
    assert float(sv_accuracy.replace("D", "E")) == nominal
    assert rinex.read_nav(tmp_path / "w.nav").kepler[0].accuracy_m == lnav.ura_m(n)


def test_galileo_sisa_and_napa():
    for index in range(126):
        assert rinex.broadcast_accuracy_m(System.GALILEO, inav.sisa_m(index)) == inav.sisa_m(index)
    # NAPA as RINEX writes it (−1), a value above the table (spare indices): no prediction (inf)
    for value in (-1.0, 6.5, 255.0, math.nan):
        assert math.isinf(rinex.broadcast_accuracy_m(System.GALILEO, value))
    assert math.isinf(inav.sisa_m(inav.SISA_NAPA))  # the UBX decoder's NAPA: the same inf


@pytest.mark.parametrize("system", [System.GPS, System.GALILEO, System.BEIDOU])
def test_accuracy_not_given_is_a_blank_field_and_no_prediction_is_not(tmp_path, system):
    """NaN ("not given") is written as a blank field and read back as NaN; inf ("no prediction") as
    RINEX writes it (Galileo NAPA −1, URA 15's 8192 m) and read back as inf; a given value as itself."""
    (g,) = _read(tmp_path, GPS_G01).kepler
    g = dataclasses.replace(g, system=int(system))
    given = inav.sisa_m(107) if system == System.GALILEO else lnav.ura_m(0)
    ephs = [dataclasses.replace(g, prn=p, accuracy_m=a)
            for p, a in ((1, math.nan), (2, math.inf), (3, given))]
    rinex.write_nav(tmp_path / "w.nav", ephs)
    body = (tmp_path / "w.nav").read_text().split("END OF HEADER\n")[1].splitlines()
    fields = [line[4:23] for line in body[6::8]]  # each record: its first line, then broadcast orbits 1-7
    assert fields[0] == " " * 19
    assert float(fields[1].replace("D", "E")) == (-1.0 if system == System.GALILEO else 8192.0)
    back = [e.accuracy_m for e in rinex.read_nav(tmp_path / "w.nav").kepler]
    assert math.isnan(back[0]) and back[1] == math.inf and back[2] == given


def test_galileo_inav_kept_fnav_counted_and_the_e1_clock_is_one(tmp_path):
    """Of E24's four records the three I/NAV ones are kept with BGD E5b/E1, the F/NAV one counted.
    Known answer: both describe the same E1 clock, F/NAV as af0(E5a,E1) − BGD(E1,E5a), I/NAV as
    af0(E5b,E1) − BGD(E1,E5b): the kept clock and the F/NAV record's E1 clock agree to 0.35 ns
    (0.1 m), while F/NAV's af0 with I/NAV's BGD (a silent mix) is 5.9 ns (1.8 m) off, and I/NAV's af0
    with BGD E5a/E1 (the wrong column) 5.6 ns."""
    nav = _read(tmp_path, GAL_E24)
    assert len(nav.kepler) == 3 and dict(nav.rejected) == {"galileo_fnav_skipped": 1}
    for e in nav.kepler:
        assert (e.system, e.prn, e.iode, e.health) == (System.GALILEO, 24, 80, 0)
        assert e.accuracy_m == inav.sisa_m(107) == 3.12
    kept = nav.kepler[-1]
    t = np.array([gps_from_calendar(2020, 5, 15, 0, 30, 0.0, "GPS")])

    def clock(e: KeplerEphemeris) -> float:
        return float(EphemerisStore([e]).states(np.array([e.system]), np.array([e.prn]), t).clock_s[0])

    fnav_af0, bgd_e5a, bgd_e5b = 5.455514357891e-03, 4.540197551250e-08, 5.098991096020e-08
    fnav_e1 = clock(dataclasses.replace(kept, af0_s=fnav_af0, tgd_s=bgd_e5a))
    assert abs(clock(kept) - fnav_e1) < 0.4e-9
    assert abs(clock(dataclasses.replace(kept, af0_s=fnav_af0)) - fnav_e1) > 5e-9
    assert abs(clock(dataclasses.replace(kept, tgd_s=bgd_e5a)) - fnav_e1) > 5e-9
    assert kept.tgd_s == bgd_e5b


@pytest.mark.parametrize(
    ("sources", "kept", "reason"),
    [
        (517, True, ""),  # I/NAV E1-B + E5b-I, clock E5b,E1
        (513, True, ""),
        (516, True, ""),
        (1, True, ""),  # I/NAV without a clock bit: I/NAV carries only the E5b,E1 pair
        (258, False, "galileo_fnav_skipped"),  # F/NAV E5a-I, clock E5a,E1
        (2, False, "galileo_fnav_skipped"),
        (257, False, "galileo_fnav_skipped"),  # I/NAV stated with the E5a,E1 clock: not the E1 user's
        (769, False, "galileo_bad_data_source"),  # both clock bits
        (512, False, "galileo_bad_data_source"),  # no source bit
        (0, False, "galileo_bad_data_source"),
    ],
)
def test_galileo_data_sources(tmp_path, sources, kept, reason):
    header, *records = GAL_E24.split("E24 2020")
    record = "E24 2020" + records[1]  # the 513 record
    assert record.count(E24_SOURCES[1]) == 1
    nav_text = header + record.replace(E24_SOURCES[1], f"{float(sources):18.12E}")
    if kept:
        assert len(_read(tmp_path, nav_text).kepler) == 1
    else:  # the only record: a one-line error that names the count
        with pytest.raises(UserError, match=f"{reason}': 1"):
            _read(tmp_path, nav_text)
    assert rinex.galileo_skip_reason(sources) == reason


# --- the same broadcast through UBX and through RINEX ---------------------------------------------


def _via_rinex(tmp_path: Path, ephs: list[KeplerEphemeris]) -> list[KeplerEphemeris]:
    p = tmp_path / "via.nav"
    rinex.write_nav(p, ephs)
    nav = rinex.read_nav(p)
    assert not nav.rejected
    return nav.kepler


def _assert_same_states(a: list[KeplerEphemeris], b: list[KeplerEphemeris], dt_s: float = 1500.0) -> None:
    assert [e.accuracy_m for e in a] == [e.accuracy_m for e in b]
    assert [(e.system, e.prn, e.iode, e.health, e.toe_gps_s, e.toc_gps_s) for e in a] == [
        (e.system, e.prn, e.iode, e.health, e.toe_gps_s, e.toc_gps_s) for e in b
    ]
    sysv = np.array([e.system for e in a])
    prn = np.array([e.prn for e in a])
    t = np.array([e.toe_gps_s + dt_s for e in a])
    # the orbits and clocks compared whatever the accuracy says (a store gives no state for inf)
    a, b = ([dataclasses.replace(e, accuracy_m=math.nan) for e in x] for x in (a, b))
    sa, sb = EphemerisStore(a).states(sysv, prn, t), EphemerisStore(b).states(sysv, prn, t)
    assert sa.valid.all() and sb.valid.all()
    assert np.abs(sa.pos_ecef_m - sb.pos_ecef_m).max() < 1e-3  # RINEX's 12 decimals: < 0.1 mm
    assert np.abs(sa.vel_ecef_m_s - sb.vel_ecef_m_s).max() < 1e-6
    assert np.abs(sa.clock_s - sb.clock_s).max() < 1e-13


def test_real_broadcasts_give_the_same_satellite_through_ubx_and_rinex(tmp_path):
    """Real GPS PRN 21 LNAV subframes, Galileo E01 I/NAV words and BeiDou C10 D1 subframes, decoded
    by the UBX path and written to a RINEX file as a converter would: the RINEX path gives the same
    accuracy (URA 2.4 m, SISA 3.12 m, URA 2.4 m), position and clock."""
    lnav_dec = LnavDecoder()
    t_gps = gps_from_calendar(2019, 7, 20, 0, 0, 0.0, "GPS")
    g = [e for w in SUBFRAMES_PRN21 if (e := lnav_dec.add(21, w, t_gps)) is not None]
    gal_dec = GalileoDecoder()
    e = [x for w in GAL_E01_WORDS
         if (x := gal_dec.add(1, inav_sfrbx_words(_word128(w)), GAL_E01_T_GPS_S)) is not None]
    bds_dec = BeidouDecoder()
    c = [x for sf in BDS_C10_SUBFRAMES if (x := bds_dec.add(10, sf)) is not None]
    ubx = g + e + c
    assert [x.accuracy_m for x in ubx] == [2.4, 3.12, 2.4]
    _assert_same_states(ubx, _via_rinex(tmp_path, ubx))


def test_simulated_sky_through_ubx_and_rinex_every_accuracy_index(tmp_path):
    """The simulator's GPS, Galileo and BeiDou ephemerides with accuracies over the whole index range
    (URA 0-15, SISA 0-125 and NAPA), encoded as the receiver sends them, decoded by the UBX path,
    then through a RINEX file: the same accuracy_m, position and clock."""
    rng = np.random.default_rng(7)
    kep, _ = constellation(1.4e9, 1.4e9 + 3600.0, (System.GPS, System.GALILEO, System.BEIDOU))
    ubx: list[KeplerEphemeris] = []
    lnav_dec, gal, bds = LnavDecoder(), GalileoDecoder(), BeidouDecoder()
    for i, eph in enumerate(kep):
        if eph.system == System.GALILEO:
            index = inav.SISA_NAPA if i % 5 == 0 else int(rng.integers(0, 126))
            eph = dataclasses.replace(eph, accuracy_m=inav.sisa_m(index))
            got = _gal_round_trip(eph, eph.toe_gps_s + 600.0, gal)
        elif eph.system == System.BEIDOU:
            eph = dataclasses.replace(eph, accuracy_m=lnav.ura_m(int(rng.integers(0, 16))))
            got = _bds_round_trip(eph, eph.toe_gps_s + 600.0, bds)
        else:
            eph = dataclasses.replace(eph, accuracy_m=lnav.ura_m(i % 16))
            week, tow = week_tow(eph.toe_gps_s + 60.0)
            got = None
            for k in (1, 2, 3):
                words = lnav_subframe(eph, k, tow + 6.0 * k, week)
                assert words is not None
                got = lnav_dec.add(eph.prn, words, eph.toe_gps_s + 60.0) or got
        assert got is not None and got.accuracy_m == eph.accuracy_m, (eph.system, eph.prn)
        ubx.append(got)
    assert {System(e.system) for e in ubx} == {System.GPS, System.GALILEO, System.BEIDOU}
    assert any(math.isinf(e.accuracy_m) for e in ubx if e.system == System.GALILEO)
    assert any(math.isinf(e.accuracy_m) for e in ubx if e.system == System.GPS)
    _assert_same_states(ubx, _via_rinex(tmp_path, ubx))


def test_simulated_glonass_through_ubx_and_rinex(tmp_path):
    """GLONASS (no broadcast accuracy is carried, see docs/gnss.md): strings 1-4 decoded by the UBX
    path, then through a RINEX file, give the same channel, health, position and clock."""
    from companion.gnss.glonav import GlonassDecoder, words_from_string
    from simvehicle.ubx import glonass_string

    _, glo = constellation(1.4e9, 1.4e9 + 3600.0, (System.GLONASS,))
    dec, ubx = GlonassDecoder(), []
    for eph in glo:
        t_frame = eph.toe_gps_s - 60.0
        strings = [glonass_string(eph, m, t_frame, t_frame + 2.0 * m) for m in (1, 2, 3, 4)]
        got = [dec.add(eph.prn, eph.channel, words_from_string(s, 7, 1), t_frame + 40.0) for s in strings]
        assert got[3] is not None
        ubx.append(got[3])
    p = tmp_path / "glo.nav"
    rinex.write_nav(p, [], ubx)
    nav = rinex.read_nav(p)
    assert not nav.rejected and len(nav.glonass) == len(ubx) > 20
    assert [(e.prn, e.channel, e.health, e.toe_gps_s) for e in nav.glonass] == [
        (e.prn, e.channel, e.health, e.toe_gps_s) for e in ubx]
    t = np.array([e.toe_gps_s + 600.0 for e in ubx])
    prn = np.array([e.prn for e in ubx])
    sysv = np.full(len(t), int(System.GLONASS))
    a, b = (EphemerisStore([], list(x)).states(sysv, prn, t) for x in (ubx, nav.glonass))
    assert a.valid.all() and np.abs(a.pos_ecef_m - b.pos_ecef_m).max() < 1e-3
    assert np.abs(a.clock_s - b.clock_s).max() < 1e-13
