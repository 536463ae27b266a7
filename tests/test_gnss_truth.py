"""Truth files in the formats urban data sets ship (``gcs_tools.gnss.truth``): a SPAN / Inertial Explorer
export, the truth CSV, smartLoc's *_GT.txt; ``gnss spp --truth`` and ``replay --truth`` on each."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.errors import UserError
from companion.gnss import timescale as ts
from companion.gnss.geometry import ecef_to_geodetic
from gcs_tools.gnss import truth
from tests.gnss_helpers import RX_ECEF, T0

DATA = Path(__file__).parent / "data"
OBS, NAV = DATA / "synthetic_gnss.obs", DATA / "synthetic_gnss.nav"  # 3 epochs at T0 + 100 + k s
V_RX = np.array([5.0, -3.0, 1.0])  # the committed RINEX's receiver moves at this from RX_ECEF

# the first two rows of UrbanNav Hong Kong's reference trajectory (UrbanNav-HK, 2021-05-17, NovAtel SPAN-CPT
# post-processed in Inertial Explorer), its two header lines as the data set ships them
URBANNAV_HK = """\
      UTCTime       Week   GPSTime         Latitude        Longitude        H-Ell VelBdyX VelBdyY VelBdyZ AccBdyX AccBdyY AccBdyZ           Roll          Pitch        Heading Q
        (sec)    (weeks)     (sec)       (+/-D M S)       (+/-D M S)          (m)   (m/s)   (m/s)   (m/s) (m/s^2) (m/s^2) (m/s^2)          (deg)          (deg)
1621218775.00 2158.00000  95593.00   22 18 04.31949  114 10 44.60559        3.472  -0.000   0.002  -0.010   0.381  -0.040   0.019  -1.7398149928   0.4409540487 -132.534729738 2
1621218776.00 2158.00000  95594.00   22 18 04.31949  114 10 44.60559        3.471  -0.000  -0.000  -0.011   0.127   0.144   0.088  -1.7380961194   0.4408681050 -132.534460448 2
"""  # noqa: E501


def test_dms_to_degrees_sign_on_the_degrees():
    assert truth.dms_to_deg("22", "18", "04.31949") == pytest.approx(22 + 18 / 60 + 4.31949 / 3600,
                                                                     abs=1e-12)
    assert truth.dms_to_deg("-33", "52", "04.1") == pytest.approx(-(33 + 52 / 60 + 4.1 / 3600), abs=1e-12)
    assert truth.dms_to_deg("-0", "30", "00.0") == -0.5  # the sign of a zero degree count is kept
    assert truth.dms_to_deg("0", "30", "00.0") == 0.5
    assert truth.dms_to_deg("-0", "00", "36.0") == -0.01
    for bad in (("10", "60", "0"), ("10", "5", "60.0"), ("10", "-5", "0")):
        with pytest.raises(ValueError):
            truth.dms_to_deg(*bad)


def test_urbannav_excerpt_gps_time_from_week_and_from_utc(tmp_path):
    """Week/GPSTime and UTCTime + 18 leap seconds give the same GPS time; the position is the DMS one."""
    span = tmp_path / "UrbanNav_reference.txt"
    span.write_text(URBANNAV_HK)
    tr = truth.read(span)
    assert tr.t_s.tolist() == [ts.gps_from_week_tow(2158, 95593.0), ts.gps_from_week_tow(2158, 95594.0)]
    assert tr.t_s[0] == ts.unix_to_gps_s(1621218775.0) == 1621218775.0 - ts.GPS_EPOCH_UNIX_S + 18.0
    lat, lon, h = ecef_to_geodetic(tr.p_ecef_m)
    np.testing.assert_allclose(np.degrees(lat), 22 + 18 / 60 + 4.31949 / 3600, atol=1e-10)
    np.testing.assert_allclose(np.degrees(lon), 114 + 10 / 60 + 44.60559 / 3600, atol=1e-10)
    np.testing.assert_allclose(h, [3.472, 3.471], atol=1e-4)
    assert tr.max_gap_s == 1.5 and not tr.rejected  # a 1 Hz reference covers the epochs between its rows
    # the same rows without Week and GPSTime: the time from UTCTime through the leap-second table
    lines = URBANNAV_HK.splitlines()
    utc_only = [lines[0].replace("Week   GPSTime", ""), lines[1].replace("(weeks)     (sec)", "")]
    utc_only += [" ".join(ln.split()[:1] + ln.split()[3:]) for ln in lines[2:]]
    (tmp_path / "utc.txt").write_text("\n".join(utc_only) + "\n")
    tr2 = truth.read(tmp_path / "utc.txt")
    assert tr2.t_s.tolist() == tr.t_s.tolist()
    np.testing.assert_array_equal(tr2.p_ecef_m, tr.p_ecef_m)


def _dms(deg: float) -> str:
    a = abs(deg)
    d, m = int(a), int((a - int(a)) * 60)
    s = (a - d - m / 60) * 3600
    return f"{'-' if deg < 0 else ''}{d} {m:02d} {s:012.9f}"


def write_span(path: Path, t_gps: np.ndarray, p_ecef: np.ndarray, dms: bool = True) -> None:
    lat, lon, h = ecef_to_geodetic(p_ecef)
    unit = "(+/-D M S)" if dms else "(deg)"
    rows = [" UTCTime Week GPSTime Latitude Longitude H-Ell Roll Q",
            f" (sec) (weeks) (sec) {unit} {unit} (m) (deg)"]
    for t, la, lo, hh in zip(t_gps, np.degrees(lat), np.degrees(lon), h, strict=True):
        week, tow = ts.week_tow(float(t))
        ll = f"{_dms(la)} {_dms(lo)}" if dms else f"{la:.12f} {lo:.12f}"
        rows.append(f"{ts.gps_to_unix_s(float(t)):.3f} {week}.00000 {tow:.6f} {ll} {hh:.6f} -1.7 2")
    path.write_text("\n".join(rows) + "\n")


def write_csv(path: Path, t_gps: np.ndarray, p_ecef: np.ndarray, form: str) -> None:
    # plain floats, whose repr is the shortest exact decimal
    t_gps, p_ecef = np.asarray(t_gps, float).tolist(), np.asarray(p_ecef, float).tolist()
    lat, lon, h = (v.tolist() for v in ecef_to_geodetic(np.array(p_ecef)))
    if form == "week-geodetic":
        rows = ["gps_week,gps_tow_s,lat_deg,lon_deg,h_m,quality"]
        rows += [f"{ts.week_tow(t)[0]},{ts.week_tow(t)[1]!r},{math.degrees(a)!r},"
                 f"{math.degrees(b)!r},{c!r},1" for t, a, b, c in zip(t_gps, lat, lon, h, strict=True)]
    else:
        rows = ["# a comment line", "t_gps_s,x_m,y_m,z_m"]
        rows += [f"{t!r},{p[0]!r},{p[1]!r},{p[2]!r}" for t, p in zip(t_gps, p_ecef, strict=True)]
    path.write_text("\n".join(rows) + "\n")


def _spp(tmp_path: Path, name: str, *truth_args: str) -> dict:
    out = tmp_path / f"out-{name}"
    r = subprocess.run([sys.executable, "-m", "gcs_tools", "gnss", "spp", str(OBS), "--nav", str(NAV),
                        *truth_args, "--out", str(out), "--json"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def _numbers(d, prefix=""):
    """A nested summary's numbers, by path."""
    if isinstance(d, dict):
        out = {}
        for k, v in d.items():
            out.update(_numbers(v, f"{prefix}{k}."))
        return out
    if isinstance(d, list):
        return _numbers(dict(enumerate(d)), prefix)
    return {prefix: math.nan if d is None else float(d)} if isinstance(d, (int, float)) or d is None else {}


def _assert_same_errors(a: dict, b: dict, atol: float = 1e-6) -> None:
    na, nb = _numbers(a["errors"]), _numbers(b["errors"])
    assert na.keys() == nb.keys()
    for k in na:
        assert na[k] == pytest.approx(nb[k], abs=atol, nan_ok=True), k


def test_static_truth_in_every_format_scores_as_truth_ecef(tmp_path):
    """The synthetic RINEX run scored against RX_ECEF given as --truth-ecef, as a SPAN export (DMS and
    decimal degrees) and as both CSV forms: the same error statistics (the receiver moves at 6 m/s, so
    the errors are metres, not zero)."""
    t = T0 + np.arange(90.0, 111.0)  # 1 Hz around the epochs
    p = np.tile(RX_ECEF, (len(t), 1))
    files = {"span.txt": lambda f: write_span(f, t, p),
             "span_deg.txt": lambda f: write_span(f, t, p, dms=False),
             "week.csv": lambda f: write_csv(f, t, p, "week-geodetic"),
             "ecef.csv": lambda f: write_csv(f, t, p, "t")}
    ref = _spp(tmp_path, "ecef", "--truth-ecef", ",".join(repr(float(v)) for v in RX_ECEF))
    assert ref["errors"]["epochs"] == 3 and ref["errors"]["horizontal_m"]["median"] > 1.0
    for name, write in files.items():
        write(tmp_path / name)
        s = _spp(tmp_path, name, "--truth", str(tmp_path / name))
        _assert_same_errors(s, ref)
        assert s["truth"].endswith(f"rows of {name}, interpolated at the epochs")
        assert "truth_rows_rejected" not in s


def test_moving_truth_in_two_formats_gives_the_same_errors(tmp_path):
    """The receiver's true track at 1 Hz (rows between the epochs' receiver-clock times): the SPAN export
    and the ECEF CSV score identically, and the solutions' errors are millimetres."""
    t = T0 + np.arange(95.0, 106.0)
    p = RX_ECEF + V_RX * (t - T0 - 100.0)[:, None]
    write_span(tmp_path / "span.txt", t, p)
    write_csv(tmp_path / "ecef.csv", t, p, "t")
    a = _spp(tmp_path, "span", "--truth", str(tmp_path / "span.txt"))
    b = _spp(tmp_path, "csv", "--truth", str(tmp_path / "ecef.csv"))
    _assert_same_errors(a, b)
    assert a["errors"]["epochs"] == 3 and a["errors"]["horizontal_m"]["p95"] < 0.01


def test_bad_rows_are_counted_and_bad_files_are_one_line(tmp_path):
    t = T0 + np.arange(95.0, 106.0)
    p = np.tile(RX_ECEF, (len(t), 1))
    write_csv(tmp_path / "ecef.csv", t, p, "t")
    lines = (tmp_path / "ecef.csv").read_text().splitlines()
    lines[4] = "oops,1,2,3"  # junk
    lines[5] = lines[5].split(",")[0] + ",nan,1,2"  # NaN
    lines[7] = lines[3]  # the time goes back
    lines[9] = "1e12" + lines[9][lines[9].index(","):]  # a damaged, lone time stamp
    lines[10] = lines[10].split(",")[0] + ",1,2,3"  # not on the Earth
    lines.append("5,6")  # short
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    tr = truth.read(tmp_path / "bad.csv")
    assert dict(tr.rejected) == {"unparsable": 1, "nonfinite": 1, "time_not_increasing": 1, "lone_stamp": 1,
                                 "off_earth": 1, "short_row": 1}
    assert len(tr.t_s) == 11 - 5 and (np.diff(tr.t_s) > 0).all()
    s = _spp(tmp_path, "bad", "--truth", str(tmp_path / "bad.csv"))
    assert s["truth_rows_rejected"]["unparsable"] == 1

    span = tmp_path / "span.txt"
    write_span(span, t, p)
    text = span.read_text().splitlines()
    text[3] = text[3].replace(" 52 30 ", " 52 61 ", 1)  # minutes out of range
    span.write_text("\n".join(text) + "\n")
    assert dict(truth.read(span).rejected) == {"unparsable": 1}

    cases = {"no header": "1,2,3\n4,5,6\n",
             "one row": "t_gps_s,x_m,y_m,z_m\n1," + ",".join(map(str, RX_ECEF)),
             "no units": " Week GPSTime Latitude Longitude H-Ell\n 2158 1 22 114 3\n"}
    for name, content in cases.items():
        (tmp_path / "t.txt").write_text(content)
        with pytest.raises(UserError) as exc:
            truth.read(tmp_path / "t.txt")
        assert "\n" not in str(exc.value), name
    bad = subprocess.run([sys.executable, "-m", "gcs_tools", "gnss", "spp", str(OBS), "--nav", str(NAV),
                          "--truth", str(tmp_path / "t.txt"), "--out", str(tmp_path / "o")],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0 and "line of units" in bad.stderr


def test_truth_on_another_time_scale_is_one_line(tmp_path):
    """A truth in UTC Unix seconds given as t_gps_s (or a smartLoc drive's seconds): covers no epoch."""
    t = T0 + np.arange(95.0, 106.0)
    write_csv(tmp_path / "unix.csv", np.array([ts.gps_to_unix_s(float(x)) for x in t]),
              np.tile(RX_ECEF, (len(t), 1)), "t")
    bad = subprocess.run([sys.executable, "-m", "gcs_tools", "gnss", "spp", str(OBS), "--nav", str(NAV),
                          "--truth", str(tmp_path / "unix.csv"), "--out", str(tmp_path / "o")],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0
    assert "covers none of the epochs" in bad.stderr and "GPS time" in bad.stderr


@pytest.mark.parametrize("coupling", ["loose", "tight"])
def test_replay_smartloc_with_its_truth_as_csv(tmp_path, capsys, coupling):
    """replay --smartloc --truth: the drive's *_GT.txt rewritten as the truth CSV (the drive's seconds in
    t_gps_s) scores as the *_GT.txt itself; a junk truth row is counted in the summary."""
    from gcs_tools.cli import main
    from gcs_tools.gnss import smartloc
    from tests.test_gnss_readers import _write_smartloc

    a, b = _write_smartloc(tmp_path)
    gt = smartloc.read_truth(b)
    write_csv(tmp_path / "truth.csv", gt.t_s, gt.p_ecef_m, "t")
    rows = (tmp_path / "truth.csv").read_text().splitlines()
    (tmp_path / "truth.csv").write_text("\n".join([*rows[:3], "junk", *rows[3:]]) + "\n")
    summaries, texts = [], []
    for name, extra in (("gt", []), ("csv", ["--truth", str(tmp_path / "truth.csv")])):
        assert main(["replay", "--smartloc", str(a), *extra, "--coupling", coupling, "--out",
                     str(tmp_path / name), "--no-figures", "--no-progress"]) == 0
        summaries.append(json.loads((tmp_path / name / "summary.json").read_text()))
        texts.append(capsys.readouterr().out)
    _assert_same_errors(*summaries, atol=1e-9)
    assert summaries[1]["samples_rejected"]["codec"]["truth_row_short_row"] == 1
    assert "to truth (smartLoc point3, geodetic)" in texts[0] and "to truth (CSV rows, geodetic)" in texts[1]
    # a log replayed with raw GNSS is scored against its own truth: --truth there is refused, not ignored
    assert main(["replay", str(DATA / "quad106.tlog"), "--rinex-obs", str(OBS), "--rinex-nav", str(NAV),
                 "--truth", str(tmp_path / "truth.csv"), "--coupling", coupling,
                 "--out", str(tmp_path / "o")]) == 2
    assert "--truth goes with --smartloc" in capsys.readouterr().err
