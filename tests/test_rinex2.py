"""RINEX 2 (2.10, 2.11) observation and navigation files: the format specification's own examples
read to their printed values; the project's RINEX 3 files rewritten as RINEX 2.11 read to the same
ephemerides, epochs and ``gnss spp`` solution; damaged files counted or one-line errors."""

from __future__ import annotations

import gzip
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.errors import UserError
from companion.gnss import lnav
from companion.gnss.systems import System
from companion.gnss.timescale import gps_from_calendar, week_tow
from gcs_tools.gnss import rinex
from tests.test_gnss_readers import NAV, OBS, _same_epochs
from tests.test_gnss_replay import QUAD106, rinex_for_quad106  # noqa: F401 - a fixture

# RINEX 2.11 specification (Gurtner & Estey, IGS/RTCM, 2007/2012), table A8: the GPS navigation
# message example, as printed (D exponents, no leading zeros, 2-digit years).
SPEC_A8_GPS_NAV = """\
     2.11           N: GPS NAV DATA                         RINEX VERSION / TYPE
XXRINEXN V2.10      AIUB                 3-SEP-99 15:22     PGM / RUN BY / DATE
EXAMPLE OF VERSION 2.11 FORMAT                              COMMENT
     .1676D-07   .2235D-07  -.1192D-06  -.1192D-06          ION ALPHA
     .1208D+06   .1310D+06  -.1310D+06  -.1966D+06          ION BETA
     .133179128170D-06  .107469588780D-12   552960     1025 DELTA-UTC: A0,A1,T,W
    13                                                      LEAP SECONDS
                                                            END OF HEADER
 6 99  9  2 17 51 44.0 -.839701388031D-03 -.165982783074D-10  .000000000000D+00
     .910000000000D+02  .934062500000D+02  .116040547840D-08  .162092304801D+00
     .484101474285D-05  .626740418375D-02  .652112066746D-05  .515365489006D+04
     .409904000000D+06 -.242143869400D-07  .329237003460D+00 -.596046447754D-07
     .111541663136D+01  .326593750000D+03  .206958726335D+01 -.638312302555D-08
     .307155651409D-09  .000000000000D+00  .102500000000D+04  .000000000000D+00
     .000000000000D+00  .000000000000D+00  .000000000000D+00  .910000000000D+02
     .406800000000D+06  .000000000000D+00
13 99  9  2 19  0  0.0  .490025617182D-03  .204636307899D-11  .000000000000D+00
     .133000000000D+03 -.963125000000D+02  .146970407622D-08  .292961152146D+01
    -.498816370964D-05  .200239347760D-02  .928156077862D-05  .515328476143D+04
     .414000000000D+06 -.279396772385D-07  .243031939942D+01 -.558793544769D-07
     .110192796930D+01  .271187500000D+03 -.232757915425D+01 -.619632953057D-08
    -.785747015231D-11  .000000000000D+00  .102500000000D+04  .000000000000D+00
     .000000000000D+00  .000000000000D+00  .000000000000D+00  .389000000000D+03
     .410400000000D+06  .000000000000D+00
"""
# A real IGS daily broadcast file: brdc2800.15n (CDDIS, version "2", 2015-10-07; georinex's test data,
# MIT): its header and the records of PRN 1, 10 (health 63) and 25 (SV accuracy 2.8 m), as published.
REAL_BRDC_15N = """\
     2              NAVIGATION DATA                         RINEX VERSION / TYPE
CCRINEXN V1.6.0 UX  CDDIS               08-OCT-15 17:31     PGM / RUN BY / DATE
IGS BROADCAST EPHEMERIS FILE                                COMMENT
    0.1490D-07  0.7451D-08 -0.1192D-06 -0.5960D-07          ION ALPHA
    0.1065D+06  0.3277D+05 -0.2621D+06 -0.6554D+05          ION BETA
   -0.931322574615D-09-0.444089209850D-14   405504     1865 DELTA-UTC: A0,A1,T,W
    17                                                      LEAP SECONDS
                                                            END OF HEADER
 1 15 10  7  0  0  0.0 0.187428668141D-05 0.795807864051D-12 0.000000000000D+00
    0.700000000000D+02-0.673437500000D+02 0.442661285405D-08-0.106626835218D+00
   -0.341422855854D-05 0.475465832278D-02 0.991858541966D-05 0.515366233826D+04
    0.259200000000D+06 0.707805156708D-07 0.197561800058D+01 0.447034835815D-07
    0.962769186081D+00 0.190156250000D+03 0.485675188401D+00-0.804783528707D-08
    0.278583024704D-10 0.100000000000D+01 0.186500000000D+04 0.000000000000D+00
    0.200000000000D+01 0.000000000000D+00 0.512227416039D-08 0.700000000000D+02
    0.259200000000D+06 0.000000000000D+00 0.000000000000D+00 0.000000000000D+00
10 15 10  7  0  0  0.0 0.203074887395D-05 0.909494701773D-12 0.000000000000D+00
    0.117000000000D+03-0.276875000000D+02 0.487556022951D-08 0.240010296400D+01
   -0.144354999065D-05 0.101386418100D-01 0.411830842495D-05 0.515364481354D+04
    0.259200000000D+06-0.223517417908D-06 0.841313314979D+00 0.763684511185D-07
    0.950244802082D+00 0.294468750000D+03 0.149353427753D+00-0.840892169391D-08
   -0.142863093678D-11 0.100000000000D+01 0.186500000000D+04 0.000000000000D+00
    0.200000000000D+01 0.630000000000D+02-0.512227416039D-08 0.117000000000D+03
    0.258270000000D+06 0.400000000000D+01 0.000000000000D+00 0.000000000000D+00
25 15 10  7  0  0  0.0-0.488185323775D-04-0.534328137292D-11 0.000000000000D+00
    0.970000000000D+02 0.503750000000D+02 0.395516474849D-08-0.186371192704D+01
    0.272504985332D-05 0.463449012022D-02 0.744499266148D-05 0.515362173080D+04
    0.259200000000D+06 0.186264514923D-07-0.124820355932D+00-0.651925802231D-07
    0.978795286867D+00 0.247500000000D+03 0.737584779412D+00-0.782711174491D-08
    0.137505727665D-09 0.100000000000D+01 0.186500000000D+04 0.000000000000D+00
    0.280000000000D+01 0.000000000000D+00 0.512227416039D-08 0.970000000000D+02
    0.252018000000D+06 0.000000000000D+00 0.000000000000D+00 0.000000000000D+00
"""
# A real reference-station file: the first two epochs of york0440.15d (NOAA CORS station YORK,
# Trimble 5700, teqc, RINEX 2.11 GPS as Compact RINEX 1.0; georinex's test data, MIT), as published:
# 11 observation types (a header continuation line, three lines a satellite), C1 and P1, S1 in dB-Hz.
REAL_YORK_15D = """\
1.0                 COMPACT RINEX FORMAT                    CRINEX VERS   / TYPE
RNX2CRX ver.4.0.6                       14-Feb-15 03:38     CRINEX PROG / DATE
     2.11           OBSERVATION DATA    G (GPS)             RINEX VERSION / TYPE
teqc  2014Jan16     NOAA/NOS/NGS/CORS   20150214 03:36:45UTCPGM / RUN BY / DATE
Solaris x86 5.10|AMD64|cc SC5.8 -xarch=amd64|=+|=+          COMMENT
teqc  2014Jan16     NOAA/NOS/NGS/CORS   20150214 03:33:06UTCCOMMENT
0000.000      (antenna height)                              COMMENT
BIT 2 OF LLI FLAGS DATA COLLECTED UNDER A/S CONDITION       COMMENT
YORK                                                        MARKER NAME
84                                                          MARKER NUMBER
Charles Harpster    PADT                                    OBSERVER / AGENCY
0220247558          TRIMBLE 5700        NP 1.00 / SP 1.22   REC # / TYPE / VERS
0220167001          TRM33429.00+GP  NONE                    ANT # / TYPE
  1122459.2250 -4763243.0070  4076945.5470                  APPROX POSITION XYZ
        0.0000        0.0000        0.0000                  ANTENNA: DELTA H/E/N
     1     1                                                WAVELENGTH FACT L1/2
    11    L1    L2    L5    C1    P1    C2    P2    C5    S1# / TYPES OF OBSERV
          S2    S5                                          # / TYPES OF OBSERV
    30.0000                                                 INTERVAL
 SNR is mapped to RINEX snr flag value [0-9]                COMMENT
  L1 & L2: min(max(int(snr_dBHz/6), 0), 9)                  COMMENT
teqc windowed: start @ 2015 Feb 13 00:00:00.000             COMMENT
teqc windowed: delta = 86400.000 sec                        COMMENT
teqc edited: all SBAS satellites excluded                   COMMENT
teqc edited: all Galileo satellites excluded                COMMENT
teqc edited: all Compass satellites excluded                COMMENT
teqc edited: all QZSS satellites excluded                   COMMENT
Forced Modulo Decimation to 30 seconds                      COMMENT
  2015     2    13     0     0    0.0000000     GPS         TIME OF FIRST OBS
                                                            END OF HEADER
&15  2 13  0  0  0.0000000  0 10G07G27G19G03G23G20G09G31G10G16

3&-5936986221 3&-4618665923  3&24482102132   3&24482104087  3&42000 3&28000  4744  4     4   4 4
3&-25704126016 3&-20009522748  3&21438983975   3&21438984657  3&50000 3&44000  4847  4     4   4 4
3&-11841697203 3&-9213788239  3&23453180558   3&23453179343  3&44000 3&32000  4745  4     4   4 4
3&-19340692233 3&-15058112843  3&24543863338   3&24543867619  3&37000 3&23000  4643  4     4   4 4
3&-36260838533 3&-28243529241  3&20609366076   3&20609362415  3&50000 3&45000  4847  4     4   4 4
3&-9511042474 3&-7397247973  3&24392315186   3&24392316009  3&41000 3&23000  4643  4     4   4 4
3&-20702741433 3&-16102649732  3&22111940234   3&22111941067  3&49000 3&41000  4846  4     4   4 4
3&-29483161249 3&-22949140025  3&23928741307   3&23928740778  3&43000 3&33000  4745  4     4   4 4
   3&24818393997     3&31000         4         4
3&-38300677174 3&-29830969547  3&20239158901   3&20239156361  3&52000 3&46000  4847  4     4   4 4
                3

-119089849 -92797122  -22662216   -22662372  -1000 -1000   6
-104171257 -81172329  -19822810   -19823365  0 0
-147237274 -114730180  -28018433   -28017819  0 -1000
56034137 43662864  10662777   10664061  1000 2000     4
-49048400 -38219520  -9333975   -9333874  0 0
-443031 -345238  -83904   -83539  1000 3000   7 4
-100474540 -78291763  -19119876   -19120048  1000 1000     7
45044185 35099331  8570584   8571350  -2000 -3000   6
3&-2760660474   -7670633     2000   45
-4763760 -3711996  -906489   -906687  -1000 0
"""
# table A12: the GLONASS navigation message example (its first record), lower-case-free "0." numbers
SPEC_A12_GLONASS_NAV = """\
     2.11           GLONASS NAV DATA                        RINEX VERSION / TYPE
ASRINEXG V1.1.0 VM  AIUB                19-FEB-98 10:42     PGM / RUN BY / DATE
STATION ZIMMERWALD                                          COMMENT
  1998     2    16    0.379979610443D-06                    CORR TO SYSTEM TIME
                                                            END OF HEADER
 3 98  2 15  0 15  0.0 0.163525342941D-03 0.363797880709D-11 0.108000000000D+05
    0.106275903320D+05-0.348924636841D+00 0.931322574615D-09 0.000000000000D+00
   -0.944422070313D+04 0.288163375854D+01 0.931322574615D-09 0.210000000000D+02
    0.212257280273D+05 0.144599342346D+01-0.186264514923D-08 0.300000000000D+01
"""
# table A14: the mixed GPS/GLONASS observation example: 14 satellites (a continuation line), C1 and
# L1 with loss-of-lock and signal-strength digits glued to the values; GPS time, LEAP SECONDS 11
SPEC_A14_MIXED_OBS = """\
     2.11           OBSERVATION DATA    M (MIXED)           RINEX VERSION / TYPE
YYRINEXO V2.8.1 VM  AIUB                 6-FEB-00 13:59     PGM / RUN BY / DATE
TST2                                                        MARKER NAME
  3851178.1849   -80151.4072  5066671.1013                  APPROX POSITION XYZ
        1.2340        0.0000        0.0000                  ANTENNA: DELTA H/E/N
     1     0                                                WAVELENGTH FACT L1/2
     2    C1    L1                                          # / TYPES OF OBSERV
    10.000                                                  INTERVAL
    11                                                      LEAP SECONDS
  2000     2     6    11    53    0.0000000     GPS         TIME OF FIRST OBS
                                                            END OF HEADER
 00  2  6 11 53  0.0000000  0 14G23G07G02G05G26G09G21R20R19R12R02R11
                                R10R03
  22576523.586   -11256947.60212
  22360162.704   -16225110.75413
  24484865.974    14662682.882 2
  21950524.331   -13784707.24912
  22507304.252     9846064.848 2
  20148742.213   -20988953.712 4
  22800149.591   -16650822.70012
  19811403.273   -25116169.741 3
  23046997.513    -3264701.688 2
  22778170.622  -821857836.745 1
  22221283.991  -988088156.884 2
  19300913.475   -83282658.19013
  20309075.579  -672668843.84713
  23397403.484  -285457101.34211
"""
# table A7: the mixed observation example with events: flags 4 (header lines), 2, 3 (a blank epoch
# field), 5, 6 (cycle slips: observation lines that are not observations) and a second site. Its
# types are P1 L1 L2 P2 L5; the RINEX 3 reader's GPS signal is C1C (P1 is C1P/C1W, never picked), so
# the test reads it once as printed and once with P1 renamed C1.
SPEC_A7_EVENTS_OBS = """\
     2.11           OBSERVATION DATA    M (MIXED)           RINEX VERSION / TYPE
BLANK OR G = GPS,  R = GLONASS,  E = GALILEO,  M = MIXED    COMMENT
XXRINEXO V9.9       AIUB                24-MAR-01 14:43     PGM / RUN BY / DATE
  4375274.       587466.      4589095.                      APPROX POSITION XYZ
     1     1                                                WAVELENGTH FACT L1/2
     1     2     6   G14   G15   G16   G17   G18   G19      WAVELENGTH FACT L1/2
     5    P1    L1    L2    P2    L5                        # / TYPES OF OBSERV
  2005     3    24    13    10   36.0000000                 TIME OF FIRST OBS
                                                            END OF HEADER
 05  3 24 13 10 36.0000000  0  4G12G09G06E11                         -.123456789
  23629347.915            .300 8         -.353    23629364.158
  20891534.648           -.120 9         -.358    20891541.292
  20607600.189           -.430 9          .394    20607605.848
                          .324 8                                          .178 7
 05  3 24 13 10 50.0000000  4  4
     1     2     2   G 9   G12                              WAVELENGTH FACT L1/2
  *** WAVELENGTH FACTOR CHANGED FOR 2 SATELLITES ***        COMMENT
      NOW 8 SATELLITES HAVE WL FACT 1 AND 2!                COMMENT
                                                            COMMENT
 05  3 24 13 10 54.0000000  0  6G12G09G06R21R22E11                   -.123456789
  23619095.450      -53875.632 8    -41981.375    23619112.008
  20886075.667      -28688.027 9    -22354.535    20886082.101
  20611072.689       18247.789 9     14219.770    20611078.410
  21345678.576       12345.567 5
  22123456.789       23456.789 5
                     65432.123 5                                     48861.586 7
 05  3 24 13 11  0.0000000  2  1
            *** FROM NOW ON KINEMATIC DATA! ***             COMMENT
 05  3 24 13 11 48.0000000  0  4G16G12G09G06                         -.123456789
  21110991.756       16119.980 7     12560.510    21110998.441
  23588424.398     -215050.557 6   -167571.734    23588439.570
  20869878.790     -113803.187 8    -88677.926    20869884.938
  20621643.727       73797.462 7     57505.177    20621649.276
                            3  4
A 9080                                                      MARKER NAME
9080.1.34                                                   MARKER NUMBER
         .9030         .0000         .0000                  ANTENNA: DELTA H/E/N
          --> THIS IS THE START OF A NEW SITE <--           COMMENT
 05  3 24 13 12  6.0000000  0  4G16G12G06G09                         -.123456987
  21112589.384       24515.877 6     19102.763 3  21112596.187
  23578228.338     -268624.234 7   -209317.284 4  23578244.398
  20625218.088       92581.207 7     72141.846 4  20625223.795
  20864539.693     -141858.836 8   -110539.435 5  20864545.943
 05  3 24 13 13  1.2345678  5  0
                            4  1
        (AN EVENT FLAG WITH SIGNIFICANT EPOCH)              COMMENT
 05  3 24 13 14 12.0000000  0  4G16G12G09G06                         -.123456012
  21124965.133       89551.30216     69779.62654  21124972.2754
  23507272.372     -212616.150 7   -165674.789 5  23507288.421
  20828010.354     -333820.093 6   -260119.395 5  20828017.129
  20650944.902      227775.130 7    177487.651 4  20650950.363
                            4  1
           *** ANTISPOOFING ON G 16 AND LOST LOCK           COMMENT
 05  3 24 13 14 12.0000000  6  2G16G09
                 123456789.0      -9876543.5
                         0.0            -0.5
                            4  2
           ---> CYCLE SLIPS THAT HAVE BEEN APPLIED TO       COMMENT
                THE OBSERVATIONS                            COMMENT
 05  3 24 13 14 48.0000000  0  4G16G12G09G06                         -.123456234
  21128884.159      110143.144 7     85825.18545  21128890.7764
  23487131.045     -318463.297 7   -248152.72824  23487146.149
  20817844.743     -387242.571 6   -301747.22925  20817851.322
  20658519.895      267583.67817    208507.26234  20658525.869
                            4  3
         ***   SATELLITE G 9   THIS EPOCH ON WLFACT 1 (L2)  COMMENT
         *** G 6 LOST LOCK AND THIS EPOCH ON WLFACT 2 (L2)  COMMENT
                (OPPOSITE TO PREVIOUS SETTINGS)             COMMENT
"""


def _write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_spec_gps_navigation_example_reads_to_its_printed_values(tmp_path):
    """Table A8: every field of PRN 6's record, D exponents without leading zeros, year 99 -> 1999,
    toc 1999-09-02 17:51:44 GPS = week 1025 (continuous, not mod 1024) second 409904, the toe of the
    record; ION ALPHA/BETA as the Klobuchar parameters; LEAP SECONDS 13."""
    nav = rinex.read_nav(_write(tmp_path, "brdc2450.99n", SPEC_A8_GPS_NAV))
    assert not nav.rejected and not nav.glonass and [e.prn for e in nav.kepler] == [6, 13]
    e = nav.kepler[0]
    toc = gps_from_calendar(1999, 9, 2, 17, 51, 44.0, "GPS")
    assert week_tow(toc) == (1025, 409904.0) and e.toc_gps_s == e.toe_gps_s == toc
    assert (e.system, e.prn, e.iode, e.health, e.toe_sow_s) == (System.GPS, 6, 91, 0, 409904.0)
    assert (e.af0_s, e.af1_s_s, e.af2_s_s2) == (-0.839701388031e-03, -0.165982783074e-10, 0.0)
    assert (e.crs_m, e.delta_n_rad_s, e.m0_rad) == (0.934062500000e02, 0.116040547840e-08, 0.162092304801)
    assert (e.cuc_rad, e.e, e.cus_rad) == (0.484101474285e-05, 0.626740418375e-02, 0.652112066746e-05)
    assert e.sqrt_a_m05 == 0.515365489006e04
    assert (e.cic_rad, e.omega0_rad, e.cis_rad) == (-0.242143869400e-07, 0.329237003460, -0.596046447754e-07)
    assert (e.i0_rad, e.crc_m, e.omega_rad) == (0.111541663136e01, 0.326593750000e03, 0.206958726335e01)
    assert (e.omega_dot_rad_s, e.idot_rad_s) == (-0.638312302555e-08, 0.307155651409e-09)
    assert e.tgd_s == 0.0 and e.accuracy_m == 2.4  # SV accuracy 0 m: URA index 0, as the UBX path gives it
    e13 = nav.kepler[1]
    assert (e13.iode, e13.toe_sow_s, e13.af0_s) == (133, 414000.0, 0.490025617182e-03)
    assert e13.toc_gps_s == gps_from_calendar(1999, 9, 2, 19, 0, 0.0, "GPS") == e13.toe_gps_s
    assert nav.klobuchar is not None and nav.leap_seconds == 13
    np.testing.assert_array_equal(nav.klobuchar[0], [0.1676e-07, 0.2235e-07, -0.1192e-06, -0.1192e-06])
    np.testing.assert_array_equal(nav.klobuchar[1], [0.1208e06, 0.1310e06, -0.1310e06, -0.1966e06])
    # lower-case d exponents (allowed by the table's note) read the same
    head, body = SPEC_A8_GPS_NAV.split("END OF HEADER\n")
    lower = rinex.read_nav(_write(tmp_path, "lower.99n", head + "END OF HEADER\n" + body.replace("D", "d")))
    assert lower.kepler == nav.kepler


def test_a_real_igs_broadcast_file(tmp_path):
    """brdc2800.15n as CDDIS published it (version "2", leading zeros, 4-value last lines): toc
    2015-10-07 00:00 GPS = week 1865 second 259200 (Wednesday), the toe; SV accuracy 2.0 m -> URA
    index 0 (2.4 m), 2.8 m -> index 1 (3.4 m); PRN 10's health 63 kept for the store to drop; the
    same file gzip-compressed (``brdc2800.15n.gz``) reads the same."""
    nav = rinex.read_nav(_write(tmp_path, "brdc2800.15n", REAL_BRDC_15N))
    assert not nav.rejected and [e.prn for e in nav.kepler] == [1, 10, 25] and nav.leap_seconds == 17
    t = gps_from_calendar(2015, 10, 7, 0, 0, 0.0, "GPS")
    assert week_tow(t) == (1865, 259200.0)
    assert all(e.toc_gps_s == e.toe_gps_s == t and e.system == System.GPS for e in nav.kepler)
    g1, g10, g25 = nav.kepler
    assert (g1.iode, g1.health, g1.tgd_s, g1.af0_s) == (70, 0, 0.512227416039e-08, 0.187428668141e-05)
    assert (g1.sqrt_a_m05, g1.e, g1.omega_rad) == (0.515366233826e04, 0.475465832278e-02, 0.485675188401)
    assert (g10.health, g10.iode, g10.tgd_s) == (63, 117, -0.512227416039e-08)
    assert (g1.accuracy_m, g25.accuracy_m) == (lnav.ura_m(0), lnav.ura_m(1)) == (2.4, 3.4)
    assert nav.klobuchar is not None
    np.testing.assert_array_equal(nav.klobuchar[0], [0.1490e-07, 0.7451e-08, -0.1192e-06, -0.5960e-07])
    np.testing.assert_array_equal(nav.klobuchar[1], [0.1065e06, 0.3277e05, -0.2621e06, -0.6554e05])
    (tmp_path / "brdc2800.15n.gz").write_bytes(gzip.compress(REAL_BRDC_15N.encode()))
    assert rinex.read_nav(tmp_path / "brdc2800.15n.gz").kepler == nav.kepler


def test_spec_glonass_navigation_example(tmp_path):
    """Table A12: slot 3 at 1998-02-15 00:15:00 UTC (the year 98), km -> m, -TauN and +GammaN as
    RINEX 3 stores them, frequency number 21; a GLONASS file beside a GPS one adds to it."""
    g = _write(tmp_path, "zimm0460.98g", SPEC_A12_GLONASS_NAV)
    (r,) = rinex.read_nav(g).glonass
    assert (r.prn, r.channel, r.health) == (3, 21, 0)
    assert r.toe_gps_s == gps_from_calendar(1998, 2, 15, 0, 15, 0.0, "UTC")
    assert week_tow(r.toe_gps_s)[1] == 15 * 60.0 + 12.0  # Sunday 00:15 UTC + 12 leap seconds
    assert (r.clock_bias_s, r.gamma_n) == (0.163525342941e-03, 0.363797880709e-11)
    assert r.pos_ecef_m == pytest.approx(
        (0.106275903320e08, -0.944422070313e07, 0.212257280273e08), rel=1e-15
    )
    assert r.vel_ecef_m_s == pytest.approx(
        (-0.348924636841e03, 0.288163375854e04, 0.144599342346e04), rel=1e-15
    )
    both = rinex.read_nav([_write(tmp_path, "a.99n", SPEC_A8_GPS_NAV), g])
    assert len(both.kepler) == 2 and both.glonass == [r] and both.klobuchar is not None


def test_spec_mixed_observation_example_with_a_continuation_line(tmp_path):
    """Table A14: 14 satellites (12 on the epoch line, 2 on its continuation line), GPS and GLONASS,
    C1 read as C1C; the epoch in GPS time as written, not moved by the header's 11 leap seconds."""
    obs = rinex.read_obs(_write(tmp_path, "tst20370.00o", SPEC_A14_MIXED_OBS))
    (ep,) = obs.epochs
    assert not obs.rejected and obs.time_system == "GPS" and obs.version == 2.11
    assert ep.t_gps_s == gps_from_calendar(2000, 2, 6, 11, 53, 0.0, "GPS")
    assert week_tow(ep.t_gps_s) == (1048, 42780.0)  # Sunday 2000-02-06, 24 weeks after 1024
    assert ep.system.tolist() == [System.GPS] * 7 + [System.GLONASS] * 7
    assert ep.prn.tolist() == [23, 7, 2, 5, 26, 9, 21, 20, 19, 12, 2, 11, 10, 3]
    assert ep.pseudorange_m[[0, 6, 7, 13]].tolist() == [
        22576523.586,
        22800149.591,
        19811403.273,
        23397403.484,
    ]
    assert np.isnan(ep.pseudorange_rate_m_s).all() and np.isnan(ep.cn0_dbhz).all()  # no D1, S1
    np.testing.assert_array_equal(obs.approx_position_ecef_m, [3851178.1849, -80151.4072, 5066671.1013])
    assert obs.obs_types[System.GPS] == ["C1C", "L1C"]
    # a GPS file ("G" in the header) may leave the system letter blank; other systems there are counted
    gps = SPEC_A14_MIXED_OBS.replace("M (MIXED)", "G (GPS)  ").replace("G23G07G02", " 23  7  2")
    obs = rinex.read_obs(_write(tmp_path, "gps.00o", gps))
    assert obs.epochs[0].prn.tolist() == [23, 7, 2, 5, 26, 9, 21] and obs.rejected == {"unknown_system": 7}
    assert (obs.epochs[0].system == System.GPS).all() and list(obs.obs_types) == [System.GPS]


def test_a_real_compact_rinex2_station_file(tmp_path):
    """york0440.15d's first epochs through the ``hatanaka`` package's CRINEX 1.0 decoder: 2015-02-13
    00:00:00 and 00:00:30 GPS, ten satellites, C1 (not P1) as the pseudorange and S1 as C/N0, the
    first epoch's values as the file states them (Compact RINEX writes a satellite's first value in
    full: ``3&24482102132`` is G07's C1, 24482102.132 m), the second decoded from its differences."""
    obs = rinex.read_obs(_write(tmp_path, "york0440.15d", REAL_YORK_15D))
    assert obs.version == 2.11 and obs.time_system == "GPS" and not obs.rejected
    assert obs.obs_types[System.GPS][:6] == ["L1C", "L2C", "L5C", "C1C", "C1P", "C2C"]
    assert [ep.t_gps_s for ep in obs.epochs] == [
        gps_from_calendar(2015, 2, 13, 0, 0, s, "GPS") for s in (0.0, 30.0)
    ]
    first, second = obs.epochs
    assert first.prn.tolist() == second.prn.tolist() == [7, 27, 19, 3, 23, 20, 9, 31, 10, 16]
    assert (first.system == System.GPS).all()
    assert first.pseudorange_m[[0, 1, 8, 9]].tolist() == [
        24482102.132,
        21438983.975,
        24818393.997,
        20239158.901,
    ]
    assert first.cn0_dbhz.tolist() == [42.0, 50.0, 44.0, 37.0, 50.0, 41.0, 49.0, 43.0, 31.0, 52.0]
    assert np.isnan(first.pseudorange_rate_m_s).all()  # no D1 in the file
    # the second epoch: C1 of G07 moved by the file's differences (−22662216 mm and so on)
    assert second.pseudorange_m[0] == 24459439.916 and second.cn0_dbhz[0] == 41.0
    np.testing.assert_array_equal(obs.approx_position_ecef_m, [1122459.2250, -4763243.0070, 4076945.5470])


def test_spec_event_example_counts_every_event_and_skips_their_lines(tmp_path):
    """Table A7: events 4 (x5), 2, 3, 5 and 6 counted, their lines skipped; as printed (P1, no C1) no
    epoch has the GPS signal: a one-line error naming the counts. With P1 renamed C1: the five flag-0
    epochs, the new site's included, GPS, GLONASS (R21, R22) and the Galileo satellite without a
    first observation counted."""
    with pytest.raises(UserError, match="no usable observation epochs") as err:
        rinex.read_obs(_write(tmp_path, "printed.05o", SPEC_A7_EVENTS_OBS))
    msg = str(err.value)
    assert "\n" not in msg and "'no_signal_G': 22, 'no_signal_E': 2" in msg and "'no_signal_R': 2" in msg
    for flag, n in ((2, 1), (3, 1), (4, 5), (5, 1), (6, 1)):
        assert f"'event_flag_{flag}': {n}" in msg
    c1 = SPEC_A7_EVENTS_OBS.replace("     5    P1    L1", "     5    C1    L1")
    obs = rinex.read_obs(_write(tmp_path, "c1.05o", c1))
    expected = {"event_flag_4": 5, "event_flag_2": 1, "event_flag_3": 1, "event_flag_5": 1, "event_flag_6": 1}
    assert obs.rejected == {**expected, "no_pseudorange": 2}  # E11 twice: its C1 field blank
    assert [ep.n for ep in obs.epochs] == [3, 5, 4, 4, 4, 4]
    seconds = [week_tow(ep.t_gps_s)[1] % 60.0 for ep in obs.epochs]
    assert seconds == pytest.approx([36.0, 54.0, 48.0, 6.0, 12.0, 48.0])
    ep = obs.epochs[1]
    assert ep.system.tolist() == [System.GPS] * 3 + [System.GLONASS] * 2
    assert ep.prn.tolist() == [12, 9, 6, 21, 22] and ep.pseudorange_m[3] == 21345678.576
    assert obs.epochs[4].pseudorange_m[0] == 21124965.133  # LLI/SSI digits glued to the next field


# --- the project's RINEX 3 files as RINEX 2.11 (a converter on the test side) -------------------------


def _v2_nav(nav3: str, letter: str) -> str:
    """The RINEX 3 navigation file's records of one system as a RINEX 2.11 file of its type:
    ``N`` (GPS, with ION ALPHA/BETA) or ``G`` (GLONASS): PRN I2, 2-digit year, F5.1 seconds, records
    one column to the left."""
    head, body = nav3.split("END OF HEADER\n")
    kind = {"G": "N: GPS NAV DATA", "R": "G: GLONASS NAV DATA"}[letter]
    out = [f"{2.11:9.2f}{'':11s}{kind:40s}RINEX VERSION / TYPE"]
    for line in head.splitlines()[1:]:
        if line.startswith(("GPSA", "GPSB")) and letter == "G":
            out.append(f"  {line[5:53]:58s}ION {'ALPHA' if line[3] == 'A' else 'BETA'}")
        elif "LEAP SECONDS" in line:
            out.append(line)
    out.append(f"{'':60s}END OF HEADER")
    keep = False
    for line in body.splitlines():
        if line[:1].strip():
            keep = line[0] == letter
            if keep:
                y, mo, d, h, mi, s = (int(x) for x in line[4:23].split())
                out.append(f"{int(line[1:3]):2d} {y % 100:02d}{mo:3d}{d:3d}{h:3d}{mi:3d}{s:5.1f}{line[23:]}")
        elif keep:
            out.append(line[1:])
    return "\n".join(out) + "\n"


V2_TYPES = ("C1", "D1", "S1", "C2", "D2", "S2")  # 6 types: two lines per satellite


def _v2_obs(obs3: str, event: bool = False) -> str:
    """The RINEX 3 observation file as RINEX 2.11: one type list (BeiDou B1I as C2, RINEX 2.12's band),
    12 satellites on the epoch line and the rest on a continuation line, five observations a line;
    the pseudoranges carry loss-of-lock 1 and signal strength 8 digits; ``event``: a comment (event
    flag 4) after the first epoch."""
    head, body = obs3.split("END OF HEADER\n")
    out = [f"{2.11:9.2f}{'':11s}{'OBSERVATION DATA':20s}{'M (MIXED)':20s}RINEX VERSION / TYPE"]
    out += [x for x in head.splitlines() if "APPROX POSITION" in x or "TIME OF FIRST OBS" in x]
    out.append(f"{len(V2_TYPES):6d}" + "".join(f"{t:>6s}" for t in V2_TYPES) + f"{'':18s}# / TYPES OF OBSERV")
    out.append(f"{'':60s}END OF HEADER")
    epochs = body.split("> ")[1:]
    for k, ep in enumerate(epochs):
        lines = ep.splitlines()
        y, mo, d, h, mi = (int(x) for x in lines[0][:16].split())
        ids = [x[:3] for x in lines[1:]]
        first = f" {y % 100:02d}{mo:3d}{d:3d}{h:3d}{mi:3d}{lines[0][16:27]}  {lines[0][29]}{len(ids):3d}"
        out.append(first + "".join(ids[:12]))
        for j in range(12, len(ids), 12):
            out.append(" " * 32 + "".join(ids[j : j + 12]))
        for x in lines[1:]:
            cells = [x[3 + 16 * j : 19 + 16 * j].ljust(16) for j in range(3)]
            cells[0] = cells[0][:14] + "18"
            slots = cells + [" " * 16] * 3 if x[0] != "C" else [" " * 16] * 3 + cells
            out += ["".join(slots[:5]).rstrip(), "".join(slots[5:]).rstrip()]
        if event and k == 0:  # an event between the first two epochs: a comment (flag 4, one header line)
            out += [f"{'':28s}4  1", f"{'REPLAY TEST EVENT':60s}COMMENT"]
    return "\n".join(out) + "\n"


def _gps_glonass(nav3: str) -> str:
    """The RINEX 3 navigation file with its GPS and GLONASS records only."""
    head, body = nav3.split("END OF HEADER\n")
    keep, out = False, []
    for line in body.splitlines():
        keep = line[0] in "GR" if line[:1].strip() else keep
        if keep:
            out.append(line)
    return head + "END OF HEADER\n" + "\n".join(out) + "\n"


def _as_rinex2(tmp_path: Path, obs3: Path, nav3: Path, event: bool = False) -> tuple[Path, Path, list[Path]]:
    """The RINEX 3 pair restricted to GPS and GLONASS (what RINEX 2.11 navigation carries), and the
    RINEX 2.11 files made from it: observations (all systems), a GPS and a GLONASS nav file."""
    text = nav3.read_text()
    v3_nav = _write(tmp_path, "gr.nav", _gps_glonass(text))
    v2_obs = _write(tmp_path, "synt0670.24o", _v2_obs(obs3.read_text(), event))
    v2_nav = [
        _write(tmp_path, "brdc0670.24n", _v2_nav(text, "G")),
        _write(tmp_path, "brdc0670.24g", _v2_nav(text, "R")),
    ]
    return v3_nav, v2_obs, v2_nav


@pytest.fixture
def pairs(tmp_path):
    """The project's RINEX 3 pair (GPS and GLONASS navigation) and its RINEX 2.11 rewrite, both with the
    same event (a comment) between the first two epochs."""
    v3_nav, v2_obs, v2_nav = _as_rinex2(tmp_path, OBS, NAV, event=True)
    first, rest = OBS.read_text().split("\n> 2024 03 07 22 01 41")
    event = f"\n>{'':30s}4  1\n{'REPLAY TEST EVENT':60s}COMMENT"
    v3_obs = _write(tmp_path, "event.obs", first + event + "\n> 2024 03 07 22 01 41" + rest)
    return (v3_obs, v3_nav), (v2_obs, v2_nav)


def test_rinex2_navigation_is_the_rinex3_navigation(pairs):
    """Every field of every GPS and GLONASS ephemeris, the Klobuchar parameters and the leap seconds."""
    (_, v3_nav), (_, v2_nav) = pairs
    text = v2_nav[0].read_text()
    assert "ION ALPHA" in text and "\n 1 24  3  7 22  0  0.0 2.000000000000D-05" in text
    v3, v2 = rinex.read_nav(v3_nav), rinex.read_nav(v2_nav)
    assert {System(e.system) for e in v3.kepler} == {System.GPS} and len(v3.glonass) > 3
    assert v2.kepler == v3.kepler and v2.glonass == v3.glonass and not v2.rejected
    assert v3.klobuchar is not None and v2.klobuchar is not None and v2.leap_seconds == v3.leap_seconds == 18
    for a, b in zip(v2.klobuchar, v3.klobuchar, strict=True):
        np.testing.assert_array_equal(a, b)


def test_rinex2_observations_are_the_rinex3_observations(pairs, tmp_path):
    """Every epoch, satellite, pseudorange, Doppler and C/N0 (15 satellites an epoch: a continuation
    line; 6 types: two lines a satellite; an event counted), plain and in the compressed forms the
    archives publish: Compact RINEX 1.0 (``.24d``), and it or the nav file in ``.Z``/``.gz``."""
    import hatanaka

    (obs3, _), (obs2, v2_nav) = pairs
    text = obs2.read_text()
    assert "\n" + " " * 32 + "R" in text and "  4  1\n" in text  # a continuation line, the event
    v3, v2 = rinex.read_obs(obs3), rinex.read_obs(obs2)
    assert min(ep.n for ep in v3.epochs) > 12 and len(v2.epochs) == len(v3.epochs) == 3
    assert _same_epochs(v2.epochs, v3.epochs) and v2.time_system == v3.time_system == "GPS"
    assert v2.rejected == v3.rejected == {"event_flag_4": 1}
    np.testing.assert_array_equal(v2.approx_position_ecef_m, v3.approx_position_ecef_m)
    crx = hatanaka.compress(obs2.read_bytes(), compression="none")
    assert crx.startswith(b"1.0 ") and b"COMPACT RINEX" in crx[:80]  # CRINEX 1.0: RINEX 2's
    forms = {
        "a.24d": crx,
        "a.24d.Z": hatanaka.compress(obs2.read_bytes(), compression="Z"),
        "a.24o.gz": gzip.compress(obs2.read_bytes()),
    }
    for name, data in forms.items():
        (tmp_path / name).write_bytes(data)
        assert _same_epochs(rinex.read_obs(tmp_path / name).epochs, v3.epochs), name
    (tmp_path / "b.24n.Z").write_bytes(hatanaka.compress(v2_nav[0].read_bytes(), compression="Z"))
    assert rinex.read_nav(tmp_path / "b.24n.Z").kepler == rinex.read_nav(v2_nav[0]).kepler


def _spp(tmp_path: Path, name: str, obs: Path, navs: list[Path]) -> tuple[str, str]:
    out = tmp_path / name
    nav_args = [a for p in navs for a in ("--nav", str(p))]
    r = subprocess.run(
        [sys.executable, "-m", "gcs_tools", "gnss", "spp", str(obs), *nav_args, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    return r.stdout.replace(str(out), "OUT").replace(obs.name, "OBS"), (out / "fixes.csv").read_text()


def test_gnss_spp_cli_solves_the_rinex2_pair_as_the_rinex3_pair(pairs, tmp_path):
    """``beliefnav gnss spp``: the same report and the same fixes, digit for digit."""
    (obs3, nav3), (obs2, navs2) = pairs
    out3, fixes3 = _spp(tmp_path, "v3", obs3, [nav3])
    out2, fixes2 = _spp(tmp_path, "v2", obs2, navs2)
    assert fixes2 == fixes3 and len(fixes3.splitlines()) == 4
    assert out2 == out3 and "3 epochs, 3 solutions" in out3 and "obs_event_flag_4 1" in out3


# --- damaged files ---------------------------------------------------------------------------------


def test_damaged_rinex2_navigation_is_counted(tmp_path):
    """A junk number and a junk PRN: each record counted (``bad_record``), the others kept; a record cut
    short at the end: ``truncated``; a navigation type not read and the withdrawn GLONASS 2.00: one
    line each."""
    lines = SPEC_A8_GPS_NAV.splitlines()
    junk = lines[:10] + [lines[10].replace(".626740418375D-02", ".62674041x375D-02")] + lines[11:]
    nav = rinex.read_nav(_write(tmp_path, "junk.99n", "\n".join(junk + lines[8:16]) + "\n"))
    assert nav.rejected == {"bad_record": 1} and [e.prn for e in nav.kepler] == [13, 6]
    bad_prn = lines[:8] + ["XX" + lines[8][2:]] + lines[9:]
    nav = rinex.read_nav(_write(tmp_path, "prn.99n", "\n".join(bad_prn) + "\n"))
    assert nav.rejected == {"bad_record": 1} and [e.prn for e in nav.kepler] == [13]
    # PRN 6 without its broadcast orbit 3 (its toe): counted, PRN 13 after it kept; a junk ION BETA
    gap = [*lines[:7], lines[7], *lines[8:11], *lines[12:]]
    gap[4] = gap[4].replace(".1310D+06", ".13x0D+06", 1)
    nav = rinex.read_nav(_write(tmp_path, "gap.99n", "\n".join(gap) + "\n"))
    assert nav.rejected == {"record_cut_short": 1, "bad_klobuchar": 1} and [e.prn for e in nav.kepler] == [13]
    assert nav.klobuchar is None
    nav = rinex.read_nav(_write(tmp_path, "cut.99n", "\n".join(lines[:-3]) + "\n"))
    assert nav.rejected == {"truncated": 1} and [e.prn for e in nav.kepler] == [6]
    with pytest.raises(UserError, match="no usable ephemeris .rejected: .'truncated': 1") as err:
        rinex.read_nav(_write(tmp_path, "only.99n", "\n".join(lines[:12]) + "\n"))
    assert "\n" not in str(err.value)
    with pytest.raises(UserError, match=r"RINEX 2 navigation type 'E': N \(GPS\), G \(GLONASS\) and H"):
        rinex.read_nav(
            _write(tmp_path, "e.99l", SPEC_A8_GPS_NAV.replace("N: GPS NAV DATA", "E: GAL NAV DATA "))
        )
    geo = SPEC_A12_GLONASS_NAV.replace("GLONASS NAV DATA", "H: GEO NAV MSG DATA")  # SBAS: counted
    with pytest.raises(UserError, match=r"no usable ephemeris \(rejected: \{'sbas_skipped': 1\}\)"):
        rinex.read_nav(_write(tmp_path, "geo.98h", geo))
    with pytest.raises(UserError, match="GLONASS navigation 2: withdrawn clock signs"):
        rinex.read_nav(_write(tmp_path, "old.98g", SPEC_A12_GLONASS_NAV.replace("     2.11", "     2.00", 1)))


def test_damaged_rinex2_observations_are_counted(tmp_path):
    """An epoch announcing more satellites than it lists (its observation lines then read as stray
    lines, not as observations), an unknown system letter, a junk number, an epoch cut short by the
    end of the file: each counted, the rest kept; a type count that does not match its list: one line."""
    head, body = SPEC_A14_MIXED_OBS.split("END OF HEADER\n")
    ep = body.splitlines()
    second = [ep[0].replace("53  0.0000000", "53 10.0000000"), ep[1].replace("R10", "X10"), *ep[2:]]
    second[6] = second[6].replace("22507304.252", "225073x4.252")  # G26
    more = [ep[0].replace("0 14G23", "0 15G23"), *ep[2:]]  # says 15, lists 12, no continuation line
    cut = [x.replace("53  0.0000000", "53 20.0000000") for x in ep[:-1]]
    text = head + "END OF HEADER\n" + "\n".join(more + ep + second + cut) + "\n"
    obs = rinex.read_obs(_write(tmp_path, "bad.00o", text))
    assert obs.rejected == {
        "bad_epoch_line": 1,
        "stray_line": 14,
        "unknown_system": 1,
        "bad_observation": 1,
        "truncated": 1,
    }
    assert [ep.n for ep in obs.epochs] == [14, 12]
    assert week_tow(obs.epochs[1].t_gps_s)[1] == 42790.0
    # an event announcing more header lines than it has (it would swallow the next epoch): counted,
    # the epoch after it read; a new type list in an event: counted, the reading ends there
    event = [f"{'':28s}4  3", f"{'A COMMENT':60s}COMMENT"]
    types = [f"{'':28s}4  1", f"     1    C1{'':48s}# / TYPES OF OBSERV"]
    obs = rinex.read_obs(
        _write(tmp_path, "ev.00o", head + "END OF HEADER\n" + "\n".join(event + ep + types + ep))
    )
    assert obs.rejected == {"bad_event_record": 1, "stray_line": 1, "obs_types_changed": 1}
    assert [ep.n for ep in obs.epochs] == [14]
    bad_types = SPEC_A14_MIXED_OBS.replace("     2    C1    L1", "     3    C1    L1")
    with pytest.raises(UserError, match="declares 3 types and lists 2"):
        rinex.read_obs(_write(tmp_path, "types.00o", bad_types))
    transit = SPEC_A14_MIXED_OBS.replace("M (MIXED)", "T (TRANSIT)")
    with pytest.raises(UserError, match="RINEX 2 satellite system 'T'; G, R, E, S and M are read"):
        rinex.read_obs(_write(tmp_path, "transit.00o", transit))
    with pytest.raises(UserError, match="without # / TYPES OF OBSERV"):
        rinex.read_obs(
            _write(tmp_path, "none.00o", SPEC_A14_MIXED_OBS.replace("# / TYPES OF OBSERV", "COMMENT"))
        )


@pytest.mark.slow
def test_tight_replay_of_the_rinex2_pair_is_the_rinex3_replay(rinex_for_quad106, tmp_path):  # noqa: F811
    """``beliefnav replay LOG --rinex-obs --rinex-nav --coupling tight`` on quad106's raw GNSS as RINEX
    2.11 (observations, GPS and GLONASS nav files) and as RINEX 3 (GPS and GLONASS nav): the same
    estimates and the same per-epoch record, digit for digit."""
    obs3, nav3, _ = rinex_for_quad106
    v3_nav, v2_obs, v2_nav = _as_rinex2(tmp_path, obs3, nav3)
    outputs = []
    for name, obs, navs in (("v3", obs3, [v3_nav]), ("v2", v2_obs, v2_nav)):
        nav_args = [a for p in navs for a in ("--rinex-nav", str(p))]
        out = tmp_path / name
        cmd = ["replay", str(QUAD106), "--rinex-obs", str(obs), *nav_args, "--coupling", "tight"]
        r = subprocess.run(
            [sys.executable, "-m", "gcs_tools", *cmd, "--out", str(out), "--no-progress", "--no-telemetry",
             "--no-figures"],  # the estimates and the record are compared, not the figures
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert r.returncode == 0, r.stderr
        outputs.append([(out / f).read_text() for f in ("estimates.csv", "gnss_epochs.csv")])
    assert outputs[1] == outputs[0] and len(outputs[0][1].splitlines()) > 600
