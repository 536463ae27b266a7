"""RINEX 3, smartLoc and UBX readers; ``beliefnav gnss spp`` end to end (synthetic files; smartLoc's
real drive when the shared data set is beside the repository)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.errors import UserError
from companion.gnss import SppConfig, System, solve_position
from companion.gnss import timescale as ts
from companion.gnss.ubx import UbxDecoder
from gcs_tools.gnss import rinex, smartloc
from gcs_tools.gnss.sources import load_input, rinex_input
from tests.gnss_helpers import CLOCKS_M, RX_ECEF, T0, constellation, observe, serve_bytes_once, store

DATA = Path(__file__).parent / "data"
OBS, NAV = DATA / "synthetic_gnss.obs", DATA / "synthetic_gnss.nav"
V_RX = np.array([5.0, -3.0, 1.0])
SMARTLOC = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "urban" / "smartloc"
if not SMARTLOC.is_dir() and os.environ.get("BELIEFNAV_SHARED"):
    SMARTLOC = Path(os.environ["BELIEFNAV_SHARED"]) / "data" / "urban" / "smartloc"


def test_committed_rinex_files_are_what_the_writer_makes(tmp_path):
    from tests.data.make_gnss_rinex import main

    main(tmp_path)
    for name in ("synthetic_gnss.obs", "synthetic_gnss.nav"):
        assert (tmp_path / name).read_text() == (DATA / name).read_text()


def test_rinex_round_trip_solves_to_millimetres():
    data = rinex_input(OBS, [NAV])
    assert len(data.epochs) == 3 and data.klobuchar is not None and not sum(data.rejected.values())
    for k, ep in enumerate(data.epochs):
        assert ep.t_gps_s == pytest.approx(T0 + 100.0 + k + CLOCKS_M[System.GPS] / 299_792_458.0, abs=1e-7)
        s = solve_position(ep, SppConfig(), klobuchar=data.klobuchar)
        np.testing.assert_allclose(s.p_ecef_m, RX_ECEF + V_RX * k, atol=5e-3)
        np.testing.assert_allclose(s.v_ecef_m_s, V_RX, atol=0.03)  # GLONASS Doppler on its channel
    assert set(data.epochs[0].systems()) == {System.GPS, System.GALILEO, System.BEIDOU, System.GLONASS}


def test_rinex_nav_values_round_trip():
    nav = rinex.read_nav(NAV)
    kep, glo = constellation()
    assert len(nav.kepler) == len(kep) and len(nav.glonass) == len(glo)
    for a, b in zip(nav.kepler, kep, strict=True):
        assert (a.system, a.prn, a.toe_gps_s, a.toc_gps_s, a.toe_sow_s) == (
            b.system,
            b.prn,
            b.toe_gps_s,
            b.toc_gps_s,
            b.toe_sow_s,
        )
        assert a.sqrt_a_m05 == pytest.approx(b.sqrt_a_m05, rel=1e-12) and a.tgd_s == b.tgd_s
    for a, b in zip(nav.glonass, glo, strict=True):
        assert a.toe_gps_s == b.toe_gps_s and a.channel == b.channel
        np.testing.assert_allclose(a.pos_ecef_m, b.pos_ecef_m, rtol=1e-12)


HAND_OBS = """\
     3.04           OBSERVATION DATA    M                   RINEX VERSION / TYPE
G    3 C1C D1C S1C                                          SYS / # / OBS TYPES
X    1 C1C                                                  SYS / # / OBS TYPES
  2020     1     1     0     0    0.0000000     {ts}         TIME OF FIRST OBS
                                                            END OF HEADER
> 2020 01 01 00 00  0.0000000  0  3
G05  20000000.123       -1000.000          45.000
X07  21000000.000
G06  22000000.000
> 2020 01 01 00 00  1.0000000  4  1
                                                            COMMENT
> 2020 01 01 00 00  2.0000000  0  2
G05  20000000.456       -1000.000          45.000
"""


@pytest.mark.parametrize("system, offset_s", [("GPS", 0.0), ("GLO", 18.0), ("BDT", 14.0), ("GAL", 0.0)])
def test_rinex_epoch_time_systems_and_bad_records(tmp_path, system, offset_s):
    p = tmp_path / "hand.obs"
    p.write_text(HAND_OBS.format(ts=system))
    obs = rinex.read_obs(p)
    week, tow = ts.week_tow(obs.epochs[0].t_gps_s)
    assert (week, tow) == (2086, 259200.0 + offset_s)  # never shifted by leap seconds in GPS time
    assert len(obs.epochs) == 1 and obs.epochs[0].n == 2
    assert obs.rejected == {"unknown_system": 0, "event_flag_4": 1, "truncated": 1} or (
        obs.rejected["event_flag_4"] == 1 and obs.rejected["truncated"] == 1
    )
    assert obs.epochs[0].pseudorange_rate_m_s[0] == pytest.approx(1000.0 * 299_792_458.0 / 1575.42e6)


def _rinex_times(tmp_path: Path, times: list[float]) -> rinex.RinexObs:
    """A RINEX file (our writer) with one 4-satellite GPS epoch at each time, in this order, read back."""
    from companion.gnss import make_epoch

    prn = [1, 5, 9, 12]
    epochs = [make_epoch(T0 + t, [int(System.GPS)] * 4, prn, [2.1e7 + 1e5 * k for k in range(4)],
                         cn0_dbhz=[45.0] * 4) for t in times]
    p = tmp_path / "order.obs"
    rinex.write_obs(p, epochs)
    return rinex.read_obs(p)


REGULAR = [float(k) for k in range(12)]  # 1 Hz


@pytest.mark.parametrize("times, dropped, reason", [
    (REGULAR[:5] + [8.0] + REGULAR[6:], [5], "lone_epoch_ahead"),  # one stamp 3 s late (a damaged digit)
    (REGULAR[:5] + [2.0] + REGULAR[6:], [5], "lone_epoch_back"),  # ... 3 s early
    (REGULAR[:5] + [5.0 + 3.2e7] + REGULAR[6:], [5], "lone_epoch_ahead"),  # a year ahead
    ([20.0] + REGULAR[1:], [0], "lone_epoch_ahead"),  # the first epoch
    (REGULAR[:-1] + [3.0], [11], "lone_epoch_back"),  # the last epoch
    (REGULAR[:4] + [5.0, 4.0] + REGULAR[6:], [4], "lone_epoch_ahead"),  # two epochs swapped: one is kept
])
def test_rinex_lone_epoch_out_of_time_order_is_counted_not_solved(tmp_path, times, dropped, reason):
    """An epoch whose stamp breaks the file's time order (a damaged digit) was solved at the wrong time by
    ``gnss spp`` and the replay: dropped and counted; every other epoch reads as before."""
    obs = _rinex_times(tmp_path, times)
    kept = [t for k, t in enumerate(times) if k not in dropped]
    assert [e.t_gps_s - T0 for e in obs.epochs] == pytest.approx(kept, abs=1e-6)
    assert dict(obs.rejected) == {reason: len(dropped)}


@pytest.mark.parametrize("times", [
    REGULAR[:6] + [t + 7200.0 for t in REGULAR[6:]],  # a gap of two hours (a daily file)
    [30.0 * k for k in range(12)],  # a station's 30 s
    REGULAR[:6] + [t - 3600.0 for t in REGULAR[6:]],  # two files joined: the time goes back, 6 epochs agree
    REGULAR[:6] + [5.0] + REGULAR[6:],  # a duplicate stamp (the replay counts it)
    [0.1 * k for k in range(30)],  # 10 Hz
])
def test_rinex_epochs_in_order_or_confirmed_are_all_read(tmp_path, times):
    obs = _rinex_times(tmp_path, times)
    assert [e.t_gps_s - T0 for e in obs.epochs] == pytest.approx(times, abs=1e-6)
    assert not obs.rejected


def test_rinex_bad_files_are_one_line_errors(tmp_path):
    p = tmp_path / "x.obs"
    p.write_text("hello\n")
    with pytest.raises(UserError, match="not a RINEX file"):
        rinex.read_obs(p)
    p.write_text(NAV.read_text())
    with pytest.raises(UserError, match="observation file was expected"):
        rinex.read_obs(p)
    p.write_text("     1.00           OBSERVATION DATA    G                   RINEX VERSION / TYPE\n")
    with pytest.raises(UserError, match=r"only RINEX 2 \(2.10, 2.11\), 3 and 4"):
        rinex.read_obs(p)
    p.write_text(OBS.read_text().split("END OF HEADER")[0])
    with pytest.raises(UserError, match="END OF HEADER"):
        rinex.read_obs(p)
    lines = NAV.read_text().splitlines()
    (tmp_path / "cut.nav").write_text("\n".join(lines[:-2]) + "\n")  # last GLONASS record cut short
    nav = rinex.read_nav(tmp_path / "cut.nav")
    assert nav.rejected["truncated"] == 1 and len(nav.glonass) == len(constellation()[1]) - 1
    bad = "\n".join(lines).replace("5.153719005580D+03", "nan", 1)
    (tmp_path / "nan.nav").write_text(bad + "\n")
    assert rinex.read_nav(tmp_path / "nan.nav").rejected["nonfinite"] == 1


def _same_epochs(a: list, b: list) -> bool:
    fields = ("system", "prn", "pseudorange_m", "pseudorange_rate_m_s", "cn0_dbhz")
    return len(a) == len(b) and all(
        x.t_gps_s == y.t_gps_s
        and all(np.array_equal(getattr(x, f), getattr(y, f), equal_nan=True) for f in fields)
        for x, y in zip(a, b, strict=True)
    )


def test_compressed_rinex_reads_as_the_plain_file(tmp_path):
    """gzip, bzip2, Compact RINEX (Hatanaka) and Compact RINEX inside gzip: the forms RINEX archives
    publish; the name does not matter, the content does."""
    import bz2
    import gzip

    import hatanaka

    plain = rinex.read_obs(OBS)
    forms = {
        "a.obs.gz": gzip.compress(OBS.read_bytes()),
        "a.obs.bz2": bz2.compress(OBS.read_bytes()),
        "a.crx": hatanaka.compress(OBS.read_bytes(), compression="none"),
        "a.crx.gz": hatanaka.compress(OBS.read_bytes(), compression="gz"),
        "renamed.obs": gzip.compress(OBS.read_bytes()),
    }
    assert b"COMPACT RINEX" in forms["a.crx"][:80]
    assert b"COMPACT RINEX" in gzip.decompress(forms["a.crx.gz"])[:80]
    for name, data in forms.items():
        (tmp_path / name).write_bytes(data)
        obs = rinex.read_obs(tmp_path / name)
        assert _same_epochs(obs.epochs, plain.epochs) and obs.rejected == plain.rejected, name
    (tmp_path / "b.nav.gz").write_bytes(gzip.compress(NAV.read_bytes()))
    nav = rinex.read_nav(tmp_path / "b.nav.gz")
    assert len(nav.kepler) == len(rinex.read_nav(NAV).kepler) and nav.klobuchar is not None
    # the raw-GNSS entry point (gnss spp, replay) recognises them, and solves as with the plain files
    plain_in = load_input(OBS, [NAV])
    for name in ("a.crx.gz", "renamed.obs"):
        packed = load_input(tmp_path / name, [tmp_path / "b.nav.gz"])
        assert packed.format == "rinex" and _same_epochs(packed.epochs, plain_in.epochs)
    (tmp_path / "cut.obs.gz").write_bytes(forms["a.obs.gz"][:-40])
    with pytest.raises(UserError, match=r"cut.obs.gz: cannot decompress"):
        rinex.read_obs(tmp_path / "cut.obs.gz")
    (tmp_path / "junk.gz").write_bytes(b"\x1f\x8b" + bytes(range(200)))
    with pytest.raises(UserError, match=r"junk.gz: cannot decompress"):
        rinex.read_obs(tmp_path / "junk.gz")


def test_a_compact_rinex_file_from_another_writer():
    """The hatanaka package's test file (RNX2CRX 4.0.8, RINEX 3.01, GPS + GLONASS + SBAS, its TIME OF
    FIRST OBS a column late): the one epoch at 2010-03-05 00:00:30 GPS, C1C picked over C1P."""
    from importlib.resources import files

    data = files("hatanaka.test.data")
    crx = rinex.read_obs(Path(str(data / "sample.crx.gz")))
    plain = rinex.read_obs(Path(str(data / "sample.rnx")))
    assert _same_epochs(crx.epochs, plain.epochs) and crx.time_system == "GPS"
    (ep,) = crx.epochs
    assert ep.t_gps_s == ts.gps_from_calendar(2010, 3, 5, 0, 0, 30.0, "GPS") == 951_782_430.0
    assert ep.prn.tolist() == [13, 19, 32, 7, 23, 31, 20, 11]
    assert ep.pseudorange_m[:2].tolist() == [24799318.768, 24597748.629]  # G13 C1C, R19 C1C
    assert ep.cn0_dbhz[1] == 47.0 and np.isnan(ep.cn0_dbhz[0])  # R19 S1C; GPS has S1P only, no S1C


def _as_rinex4(nav3: str) -> str:
    """The RINEX 3 navigation file as RINEX 4 writes it: ``>`` frames, lower-case exponents, the
    Klobuchar parameters in an ``ION`` record, GLONASS with its fourth orbit line, and records of
    kinds the reader skips (a CNAV ephemeris, a system time offset)."""
    head, body = nav3.split("END OF HEADER\n")
    alpha = beta = ""
    out_head = []
    for line in (head + "END OF HEADER").splitlines():
        if line.startswith("GPSA"):
            alpha = line
        elif line.startswith("GPSB"):
            beta = line
        else:
            out_head.append(line)
    out_head[0] = "     4.00" + out_head[0][9:]
    a, b = ([float(x.replace("D", "E")) for x in line[4:60].split()] for line in (alpha, beta))
    ion = [
        "> ION G   LNAV",
        "    2024 03 07 22 00 00" + "".join(f"{x:19.12e}" for x in a[:3]),
        "    " + "".join(f"{x:19.12e}" for x in [a[3], *b[:3]]),
        "    " + "".join(f"{x:19.12e}" for x in [b[3], 1.0]),
    ]
    msg = {"G": "LNAV", "J": "LNAV", "E": "INAV", "C": "D1", "R": "FDMA"}
    out = (
        out_head + ion + ["> STO G01 LNAV", "    2024 03 07 22 00 00 GPUT  UTC(USNO)", "    1.0e-09 0.0e+00"]
    )
    lines = body.splitlines()
    for i, line in enumerate(lines):
        if line[:1].strip():
            if line[0] == "G" and line[1:3] == "01":  # a CNAV record of the same satellite: skipped
                out += ["> EPH G01 CNAV", *(["     0.000000000000e+00"] * 9)]
            out.append(f"> EPH {line[:3]} {msg[line[0]]}")
        out.append(line.replace("D", "e"))
        nxt = lines[i + 1] if i + 1 < len(lines) else "X"
        if out[-1].startswith("     ") and nxt[:1].strip() and any(o.startswith("> EPH R") for o in out[-5:]):
            out.append("     0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00")
    return "\n".join(out) + "\n"


def test_rinex4_navigation_reads_as_rinex3(tmp_path):
    v3 = rinex.read_nav(NAV)
    text = _as_rinex4(NAV.read_text())
    assert "IONOSPHERIC CORR" not in text and "> EPH R01 FDMA" in text and "D+" not in text
    (tmp_path / "v4.rnx").write_text(text)
    v4 = rinex.read_nav(tmp_path / "v4.rnx")
    assert v4.kepler == v3.kepler and v4.glonass == v3.glonass and v4.leap_seconds == v3.leap_seconds
    assert v3.klobuchar is not None and v4.klobuchar is not None
    for x, y in zip(v4.klobuchar, v3.klobuchar, strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-12)
    assert dict(v4.rejected) == {"v4_eph_skipped": 1, "v4_sto_skipped": 1}
    # one epoch of the observation file solved with it, as with the RINEX 3 file
    data3, data4 = rinex_input(OBS, [NAV]), rinex_input(OBS, [tmp_path / "v4.rnx"])
    s3, s4 = (solve_position(d.epochs[0], SppConfig(), klobuchar=d.klobuchar) for d in (data3, data4))
    np.testing.assert_allclose(s4.p_ecef_m, s3.p_ecef_m, atol=1e-6)
    # damaged frames are counted, the rest kept: an ephemeris cut short, an ION record of junk, a bare '>'
    lines = text.splitlines()
    g02 = lines.index("> EPH G02 LNAV")
    ion = lines.index("> ION G   LNAV")
    damaged = lines[: ion + 1] + ["    junk junk junk"] + lines[ion + 4 : g02 + 4] + [">"] + lines[g02 + 9 :]
    (tmp_path / "bad.rnx").write_text("\n".join(damaged) + "\n")
    bad = rinex.read_nav(tmp_path / "bad.rnx")
    assert bad.rejected["bad_record"] == 2 and bad.rejected["v4_empty_skipped"] == 1
    assert len(bad.kepler) == len(v3.kepler) - 1 and bad.klobuchar is None and bad.glonass == v3.glonass
    (tmp_path / "v5.rnx").write_text(text.replace("     4.00", "     5.00", 1))
    with pytest.raises(UserError, match=r"only RINEX 2 \(2.10, 2.11\), 3 and 4"):
        rinex.read_nav(tmp_path / "v5.rnx")


# --- smartLoc ---------------------------------------------------------------------------------


def _write_smartloc(tmp_path: Path) -> tuple[Path, Path]:
    """A smartLoc-format drive from the synthetic constellation: corrected pseudoranges + truth."""
    st = store()
    inp, gt = [], []
    from companion.gnss import attach_broadcast

    for k in range(8):
        t = 0.2 * k
        p = RX_ECEF + V_RX * t
        ep, _ = observe(st, T0 + 100.0 + t, p, atmosphere=False)
        ep, _ = attach_broadcast(ep, st)
        y = ep.pseudorange_m + 299_792_458.0 * ep.sat_clock_s
        code = {0: 1, 6: 4, 2: 8, 3: 32}
        for i in range(ep.n):
            sid = ep.prn[i] + (300 if ep.system[i] == 6 else 0)
            x = ep.sat_pos_ecef_m[i]
            inp.append(
                f"pseudorange3 {t} {y[i]:.4f} 25 {x[0]:.4f} {x[1]:.4f} {x[2]:.4f} {sid} "
                f"{code[int(ep.system[i])]} 40 {ep.cn0_dbhz[i]:.0f}"
            )
        inp.append(f"odom3 {t} 5.9 0 0 0 0 0.01 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06")
        gt.append(f"point3 {t} {p[0]:.4f} {p[1]:.4f} {p[2]:.4f} 0 0 0 0 0 0 0 0 0")
    inp += [
        "pseudorange3 1.0 nan 25 1 2 3 5 1 40 40",
        "pseudorange3 1.0 2e7 25 1 2 3 5 64 40 40",
        "pseudorange3 oops",
        "weird 1 2 3",
    ]
    a, b = tmp_path / "Drive_Input.txt", tmp_path / "Drive_GT.txt"
    a.write_text("\n".join(inp) + "\n")
    b.write_text("\n".join(gt) + "\n")
    return a, b


def test_smartloc_reader_counts_bad_rows(tmp_path):
    a, b = _write_smartloc(tmp_path)
    data = smartloc.read_input(a)
    assert len(data.epochs) == 8 and data.odometry.shape == (8, 3)
    assert dict(data.rejected) == {
        "nonfinite": 1,
        "unknown_system": 1,
        "unparsable": 1,
        "unknown_row_type": 1,
    }
    e = data.epochs[0]
    assert e.corrected and e.time_base == "dataset" and (e.system == System.GLONASS).any()
    assert e.prn[e.system == System.GLONASS].max() < 30
    s = solve_position(e, SppConfig())
    np.testing.assert_allclose(s.p_ecef_m, RX_ECEF, atol=5e-3)
    assert smartloc.default_truth_path(a) == b
    (tmp_path / "empty_Input.txt").write_text("odom3 0 1 0 0 0 0 0 0 0 0 0 0 0\n")
    with pytest.raises(UserError, match="no usable smartLoc"):
        smartloc.read_input(tmp_path / "empty_Input.txt")


def test_gnss_spp_cli_writes_the_error_csv(tmp_path):
    a, _ = _write_smartloc(tmp_path)
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "gcs_tools", "gnss", "spp", str(a), "--out", str(out), "--variants"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    lines = (out / "spp_errors.csv").read_text().splitlines()
    assert lines[0] == "t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m" and len(lines) == 9
    rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    np.testing.assert_allclose(rows[:, 0], 0.2 * np.arange(8), atol=1e-6)
    assert np.abs(rows[:, 1:4]).max() < 0.01 and (rows[:, 4] > 0).all()
    assert "no Earth rotation" in r.stdout
    assert "input rows skipped: nonfinite 1, unknown_row_type 1, unknown_system 1, unparsable 1" in r.stdout
    bad = subprocess.run(
        [sys.executable, "-m", "gcs_tools", "gnss", "spp", str(tmp_path / "none.txt")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0 and "no such file" in bad.stderr


def test_smartloc_row_with_a_lone_damaged_time_is_skipped_not_an_epoch(tmp_path):
    """One pseudorange row stamped 1e6 s inside a 1.6 s drive: skipped and counted (as an epoch it made
    the tight replay synthesise IMU samples up to 1e6 s: 50 M samples, minutes); a truth row so
    stamped is one line naming it."""
    from gcs_tools.cli import main

    a, b = _write_smartloc(tmp_path)
    lines = a.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("pseudorange3 0.4 "))
    lines[k] = lines[k].replace("pseudorange3 0.4 ", "pseudorange3 1000000.0 ", 1)
    a.write_text("\n".join(lines) + "\n")
    data = smartloc.read_input(a)
    assert data.rejected["lone_stamp"] == 1 and len(data.epochs) == 8
    assert max(e.t_gps_s for e in data.epochs) < 2.0
    assert main(["replay", "--smartloc", str(a), "--coupling", "tight", "--out", str(tmp_path / "o"),
                 "--no-figures", "--no-progress"]) == 0
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["duration_s"] < 5.0
    gt = b.read_text().splitlines()
    gt[3] = gt[3].replace("point3 0.6000000000000001 ", "point3 1000000.0 ", 1).replace(
        "point3 0.6 ", "point3 1000000.0 ", 1)
    b.write_text("\n".join(gt) + "\n")
    with pytest.raises(UserError, match="point3 row 4 at 1e\\+06 s lies more than 10 s"):
        smartloc.read_truth(b)


@pytest.mark.parametrize("coupling", ["loose", "tight"])
def test_replay_smartloc_far_home_is_one_line(tmp_path, capsys, coupling):
    """--home thousands of km from the drive: the numbers were silently wrong (Berlin: 29 m instead of
    18 m median); refused as for a log."""
    from gcs_tools.cli import main

    a, _ = _write_smartloc(tmp_path)
    assert main(["replay", "--smartloc", str(a), "--coupling", coupling, "--home", "10,10,0",
                 "--out", str(tmp_path / "o"), "--no-figures", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "km from the log's first 3-D fix" in err and "not flown there" in err
    assert not (tmp_path / "o").exists()


def test_gnss_spp_report_names_skipped_rows_not_a_ubx_decoders_counters():
    from gcs_tools.gnss.cli import report

    base = {"input": "x", "epochs": 3, "solutions": 3, "raim_exclusions": 0,
            "config": {"weighting": "cn0-elevation", "raim": False, "earth_rotation": True}}
    text = report({**base, "format": "smartloc", "rejected": {"nonfinite": 2, "unparsable": 0}})
    assert "input rows skipped: nonfinite 2\n" in text + "\n" and "unparsable" not in text
    assert "skipped" not in report({**base, "format": "ubx", "rejected": {"rawx_epochs": 3, "pvt": 3}})


def test_gnss_spp_truth_ecef_is_not_overridden_by_the_truth_beside(tmp_path, capsys):
    """--truth-ecef on a smartLoc input with its *_GT.txt beside: the static truth is used (it was
    silently ignored, even when malformed); with --truth as well, one line."""
    from gcs_tools.cli import main

    a, b = _write_smartloc(tmp_path)
    out = tmp_path / "o"
    ecef = ",".join(f"{v:.3f}" for v in RX_ECEF)
    assert main(["gnss", "spp", str(a), "--truth-ecef", ecef, "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["truth"] == "a static position (--truth-ecef)"
    assert main(["gnss", "spp", str(a), "--truth-ecef", "1,2", "--out", str(out)]) == 2
    assert "--truth-ecef '1,2': expected X,Y,Z" in capsys.readouterr().err
    assert main(["gnss", "spp", str(a), "--truth", str(b), "--truth-ecef", ecef, "--out", str(out)]) == 2
    assert "two truths; give one" in capsys.readouterr().err


@pytest.mark.parametrize("coupling", ["loose", "tight"])
def test_replay_smartloc_counts_the_rows_it_skipped(tmp_path, capsys, coupling):
    """A garbage line, a NaN pseudorange, an unknown system: left out and said so in the replay's
    'refused while reading' and its summary, not 'none'."""
    from gcs_tools.cli import main

    a, _ = _write_smartloc(tmp_path)
    out = tmp_path / coupling
    assert main(["replay", "--smartloc", str(a), "--coupling", coupling, "--out", str(out),
                 "--no-figures", "--no-progress"]) == 0
    refused = capsys.readouterr().out.split("refused while reading: ")[1].splitlines()[0].split(", ")
    assert sorted(refused) == ["smartloc row nonfinite 1", "smartloc row unknown row type 1",
                               "smartloc row unknown system 1", "smartloc row unparsable 1"]
    codec = json.loads((out / "summary.json").read_text())["samples_rejected"]["codec"]
    assert codec == {"smartloc_row_nonfinite": 1, "smartloc_row_unknown_row_type": 1,
                     "smartloc_row_unknown_system": 1, "smartloc_row_unparsable": 1}


def test_smartloc_real_drive_baseline():
    """smartLoc Berlin Potsdamer Platz (TU Chemnitz, CC BY-SA 4.0): the urban single-point baseline."""
    inp = SMARTLOC / "Berlin_Potsdamer_Platz_Input.txt"
    if not inp.is_file():
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"the smartLoc data set is required in CI: {inp} is missing")
        pytest.skip(f"smartLoc data set not found at {inp} (shared directory beside the repository)")
    from gcs_tools.gnss.cli import evaluate

    data = load_input(inp)
    s, _, err = evaluate(data, SppConfig())
    e = s["errors"]
    # deep urban canyon: tens of metres, almost never within 5 m; the Sagnac term worth ~25 m east
    assert s["solutions"] == len(data.epochs) > 1300
    assert 10.0 < e["horizontal_m"]["median"] < 25.0 and 35.0 < e["horizontal_m"]["p95"] < 70.0
    assert e["percent_above_5m"] > 85.0
    assert s["residuals_at_truth_m"]["GLO"]["15-30deg"]["median"] > 20.0
    no_rot = evaluate(data, SppConfig(earth_rotation=False))[0]["errors"]
    assert no_rot["mean_ned_m"][1] - e["mean_ned_m"][1] > 15.0


# --- UBX ----------------------------------------------------------------------------------------


def _ubx_frames() -> bytes:
    from pyubx2 import GET, UBXMessage

    from tests.gnss_helpers_lnav import SUBFRAMES_PRN21

    week, tow = 2062, 597000.5
    meas = {"rcvTow": tow, "week": week, "leapS": 18, "numMeas": 3, "version": 1}
    rows = [
        (0, 21, 0, 0, 21_000_000.25, -500.0, 41, 3),
        (6, 4, 0, 13, 20_500_000.0, 1000.0, 35, 5),
        (0, 21, 3, 0, 21_000_010.0, -400.0, 30, 4),
    ]  # the third: GPS L2C, not taken
    for i, (g, sv, sig, fid, pr, do, cno, prstd) in enumerate(rows, 1):
        meas.update(
            {
                f"gnssId_{i:02d}": g,
                f"svId_{i:02d}": sv,
                f"sigId_{i:02d}": sig,
                f"freqId_{i:02d}": fid,
                f"prMes_{i:02d}": pr,
                f"doMes_{i:02d}": do,
                f"cno_{i:02d}": cno,
                f"prStd_{i:02d}": prstd,
                f"prValid_{i:02d}": 1,
                f"locktime_{i:02d}": 1000,
            }
        )
    frames = [
        UBXMessage("NAV", "NAV-SAT", GET, iTOW=int(tow * 1000), version=1, numSvs=1, gnssId_01=0,
                   svId_01=21, cno_01=41, elev_01=33, azim_01=250).serialize(),
        UBXMessage("RXM", "RXM-RAWX", GET, **meas).serialize(),
        b"line noise between frames",
    ]
    for words in SUBFRAMES_PRN21:
        frames.append(
            UBXMessage("RXM", "RXM-SFRBX", GET, gnssId=0, svId=21, numWords=10, version=2,
                       **{f"dwrd_{i:02d}": w for i, w in enumerate(words, 1)}).serialize()
        )
    frames.append(
        UBXMessage("NAV", "NAV-PVT", GET, iTOW=int(tow * 1000), year=2019, month=7, day=20, hour=21, min=50,
                   second=0, validDate=1, validTime=1, fixType=3, lat=50.8, lon=12.9, height=350_000,
                   hMSL=305_000, hAcc=2500, vAcc=4000, numSV=9, velN=1000, velE=-500, velD=20, sAcc=150,
                   pDOP=1.8).serialize()
    )
    frames.append(
        UBXMessage("RXM", "RXM-RAWX", GET, **{**meas, "week": week, "rcvTow": tow + 1.0}).serialize()
    )
    return b"".join(frames)


def test_ubx_frames_decode_to_epochs_fixes_and_ephemerides(tmp_path):
    from gcs_tools.gnss.ubx_source import open_stream, read_ubx_file, ubx_items

    p = tmp_path / "rx.ubx"
    p.write_bytes(_ubx_frames())
    dec = UbxDecoder()
    with open_stream(str(p)) as f:
        items = list(ubx_items(f, dec))
    kinds = [type(i).__name__ for i in items]
    assert kinds == ["GnssEpoch", "KeplerEphemeris", "ReceiverPvt", "GnssEpoch"], kinds
    ep, eph, pvt = items[0], items[1], items[2]
    assert ep.t_gps_s == ts.gps_from_week_tow(2062, 597000.5) and ep.n == 2
    assert list(ep.system) == [System.GPS, System.GLONASS] and dec.counters["rawx_other_signal"] == 2
    lam_glo = 299_792_458.0 / (1602e6 + (13 - 7) * 0.5625e6)
    np.testing.assert_allclose(
        ep.pseudorange_rate_m_s, [500.0 * 299_792_458.0 / 1575.42e6, -1000.0 * lam_glo]
    )
    np.testing.assert_allclose(ep.pseudorange_var_m2, [(0.01 * 8) ** 2, (0.01 * 32) ** 2])
    assert ep.elevation_deg[0] == 33.0 and np.isnan(ep.elevation_deg[1])
    assert (eph.prn, eph.iode) == (21, 78) and ts.week_tow(eph.toe_gps_s) == (2062, 597600.0)
    assert (pvt.h_acc_m, pvt.v_acc_m, pvt.height_msl_m, pvt.v_ned_m_s) == (2.5, 4.0, 305.0, (1.0, -0.5, 0.02))
    assert pvt.t_utc_gps_s == ts.gps_from_calendar(2019, 7, 20, 21, 50, 0.0, "UTC")
    assert dec.counters["sfrbx_before_week"] == 0 and dec.counters["lnav_ephemerides"] == 1
    data = read_ubx_file(p)  # G21 placed by its decoded ephemeris; GLONASS has none
    assert len(data.epochs) == 2 and data.rejected["no_ephemeris"] == 2
    assert 2.0e7 < np.linalg.norm(data.epochs[0].sat_pos_ecef_m[0]) < 2.7e7


def test_ubx_from_a_tcp_stream():
    from gcs_tools.gnss.ubx_source import open_stream, ubx_items

    with serve_bytes_once(_ubx_frames(), 97) as port:  # in odd-sized pieces
        stream = open_stream(f"tcp:127.0.0.1:{port}")
        try:
            items = list(ubx_items(stream))
        finally:
            stream.close()
    assert [type(i).__name__ for i in items] == ["GnssEpoch", "KeplerEphemeris", "ReceiverPvt", "GnssEpoch"]
    with pytest.raises(UserError, match="cannot connect"):
        open_stream(f"tcp:127.0.0.1:{port}", timeout_s=1.0)
