"""Fuzz the file readers (seeded): RINEX observation and navigation files, smartLoc drives, UBX logs,
DataFlash and ULog logs, error series, truth files and the companion's config, through the real
commands. Each damaged file ends in a result (exit 0, the damage counted) or in one line (exit 2);
never a traceback, never a hang. And the regressions those mutations found, as known answers."""

from __future__ import annotations

import contextlib
import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gcs_tools.cli import main
from gcs_tools.gnss import rinex
from tests.fuzz_mutations import mutations

DATA = Path(__file__).parent / "data"
OBS, NAV = DATA / "synthetic_gnss.obs", DATA / "synthetic_gnss.nav"
REAL = DATA / "real_rinex3"
STATION_OBS, REAL_NAV = REAL / "3034265G_excerpt.21O", REAL / "SEPT2650_excerpt.21P"
STATION_ECEF = "-3959400.631,3385704.533,3667523.111"


def _run(argv: list[str]) -> tuple[int, str]:
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        rc = main(argv)
    return rc, err.getvalue()


def _fuzz(tmp_path: Path, source: bytes, suffix: str, argv: Callable[[Path], list[str]], n: int, seed: int,
          text: bool = True) -> dict[int, int]:
    """Every mutation through the command: exit 0, or exit 2 with one line on stderr."""
    rcs: dict[int, int] = {}
    for name, data in mutations(np.random.default_rng(seed), source, n, text=text):
        path = tmp_path / f"{name}{suffix}"
        path.write_bytes(data)
        rc, err = _run(argv(path))
        assert rc in (0, 2), (name, err)
        assert rc == 0 or (err.count("\n") == 1 and err.startswith("beliefnav: error: ")), (name, err)
        rcs[rc] = rcs.get(rc, 0) + 1
    return rcs


# --- RINEX ----------------------------------------------------------------------------------------

def test_rinex3_epoch_with_a_negative_satellite_count_is_counted_not_a_hang(tmp_path):
    """``> 2024 03 07 22 01 40.0000100  0 -3``: the count stepped the reader back onto the same line
    (an endless loop); now a bad epoch line, its satellite lines stray."""
    lines = OBS.read_text().splitlines()
    lines[8] = lines[8][:32] + " -3"
    path = tmp_path / "neg.obs"
    path.write_text("\n".join(lines) + "\n")
    obs = rinex.read_obs(path)
    assert len(obs.epochs) == 2
    assert obs.rejected["bad_epoch_line"] == 1 and obs.rejected["stray_line"] == 15


def test_rinex_nav_fields_out_of_range_are_bad_records(tmp_path):
    """A GPS week of -1e308 (the toe overflowed: OverflowError) and a GLONASS frequency number of 1e308
    (accepted, it crashed the observation reader's channel table; RINEX 2 ones run 1-24): each record
    counted, the rest read."""
    lines = NAV.read_text().splitlines()
    assert lines[5].startswith("G01") and lines[285].startswith("R01")
    lines[10] = lines[10][:42] + "-1.00000000000D+308" + lines[10][61:]  # G01's week
    lines[287] = lines[287][:61] + " 1.00000000000D+308"  # R01's frequency number
    path = tmp_path / "bad.nav"
    path.write_text("\n".join(lines) + "\n")
    nav = rinex.read_nav(path)
    assert (len(nav.kepler), len(nav.glonass), nav.rejected) == (34, 5, {"bad_record": 2})
    assert {e.prn for e in nav.kepler if e.system == 0} == set(range(2, 25))
    rc, err = _run(["gnss", "spp", str(OBS), "--nav", str(path), "--out", str(tmp_path / "o")])
    assert rc == 0, err


def test_rinex_obs_doppler_and_cn0_no_receiver_gives_are_counted(tmp_path):
    """A C/N0 of -3552 dB-Hz weighed its satellite to nothing (σ = inf): the solver's normal matrix went
    singular (LinAlgError). NaN, inf and out-of-range Doppler and C/N0 fields are now counted; blank
    fields (not observed) are not."""
    lines = OBS.read_text().splitlines()
    assert lines[9].startswith("G01") and lines[10].startswith("G04")
    lines[9] = lines[9][:35] + "-3552.".rjust(14)  # G01's S1C
    lines[10] = lines[10][:19] + "nan".rjust(14) + lines[10][33:]  # G04's D1C
    lines[11] = lines[11][:19] + " " * 14 + lines[11][33:]  # G08's D1C not observed: kept
    path = tmp_path / "bad.obs"
    path.write_text("\n".join(lines) + "\n")
    obs = rinex.read_obs(path)
    assert obs.rejected == {"bad_cn0": 1, "bad_doppler": 1}
    assert [e.n for e in obs.epochs] == [13, 15, 15]
    assert np.isnan(obs.epochs[0].pseudorange_rate_m_s).sum() == 1
    rc, err = _run(["gnss", "spp", str(path), "--nav", str(NAV), "--out", str(tmp_path / "o")])
    assert rc == 0, err


# --- flight logs ----------------------------------------------------------------------------------

def test_log_imu_beyond_full_scale_is_counted_not_fused(tmp_path):
    """A damaged ULog sensor_combined of 1e36 m/s² was fused: the covariance went negative and the
    replay raised (math domain error). ULog and DataFlash IMU samples beyond the MAVLink codec's full
    scale (16 g, 35 rad/s a axis) are now counted (imu_out_of_range), as the codec counts them."""
    from dataflash_writer import OLD_FORMATS, DataFlashWriter

    from companion.domain.samples import ImuSample
    from gcs_tools.replay.dataflash import DataFlashSource
    from gcs_tools.replay.ulog import _imu

    rows = [(0.1, 0.0, 0.0, -9.8), (0.0, 0.0, 1e36, -9.8), (40.0, 0.0, 0.0, -9.8), (float("nan"), 0, 0, 0),
            (-34.9, 0.0, 0.0, -156.0)]
    names = ["timestamp", *(f"gyro_rad[{i}]" for i in range(3)),
             *(f"accelerometer_m_s2[{i}]" for i in range(3))]
    arr = np.array([(1000 * k, g, 0.0, 0.0, 0.0, a, f) for k, (g, _, a, f) in enumerate(rows)],
                   dtype=[(n, "<u8" if n == "timestamp" else "<f4") for n in names])
    got = _imu(arr)
    assert [x if isinstance(x, str) else "ok" for x in got] == [
        "ok", "imu_out_of_range", "imu_out_of_range", "imu_non_finite", "ok"]
    w = DataFlashWriter()
    w.define(*OLD_FORMATS["IMU"][:1], "IMU", *OLD_FORMATS["IMU"][1:])
    for k, (g, _, a, f) in enumerate(rows):
        w.add("IMU", 1000 + 20 * k, g, 0.0, 0.0, 0.0, a, f, 0, 0)
    (tmp_path / "imu.bin").write_bytes(bytes(w.data))
    src = DataFlashSource(tmp_path / "imu.bin")
    assert sum(type(e) is ImuSample for e in src) == 2
    assert src.stats.rejected["imu_out_of_range"] == 2 and src.stats.rejected["imu_non_finite"] == 1


def test_ansfl_imu_row_beyond_full_scale_is_counted_not_fused(tmp_path):
    """An ANSFL IMU_1.csv row with Acc_X 1e30 (and one with Gyr_Y 1e30) was fused: the replay went on
    to a track 1e27 m away, exit 0. Now counted (imu_out_of_range) and the track stays metres."""
    import json

    from ansfl_helpers import write_flight

    write_flight(tmp_path / "f", seconds=8.0)
    path = tmp_path / "f" / "IMU_1.csv"
    lines = path.read_text().split("\n")
    for row, col in ((200, 4), (300, 8)):
        fields = lines[row].split(",")
        fields[col] = "1e30"
        lines[row] = ",".join(fields)
    path.write_text("\n".join(lines))
    rc, err = _run(["replay", str(tmp_path / "f"), "--gnss-errors", "none", "--out", str(tmp_path / "o"),
                    "--no-progress", "--no-telemetry", "--no-figures"])
    assert rc == 0, err
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["samples_rejected"]["codec"]["imu_out_of_range"] == 2
    assert s["errors"]["truth"]["error_horizontal_m"]["max"] < 20.0


# --- the seeded fuzz: every reader through its command ---------------------------------------------

SPP = ["gnss", "spp"]
REPLAY_FLAGS = ["--no-progress", "--no-telemetry", "--no-figures"]


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> dict[str, Path]:
    """Undamaged inputs of every reader: RINEX 2 and 4 made from the committed RINEX 3 pair, a smartLoc
    drive, truth files, a UBX log, an error series, an ANSFL flight, a quad106 head with its RINEX."""
    from ansfl_helpers import write_flight

    from tests.gnss_helpers import RX_ECEF, T0
    from tests.test_gnss_readers import _as_rinex4, _ubx_frames, _write_smartloc
    from tests.test_gnss_truth import V_RX, write_csv, write_span
    from tests.test_rinex2 import _as_rinex2

    d = tmp_path_factory.mktemp("sources")
    _, obs2, (nav2g, nav2r) = _as_rinex2(d, OBS, NAV)
    (d / "v4.rnx").write_text(_as_rinex4(NAV.read_text()))
    drive, gt = _write_smartloc(d)
    _with_imu_rows(drive, d / "imu_Input.txt")
    t = T0 + np.arange(95.0, 106.0)
    p = RX_ECEF + V_RX * (t - T0 - 100.0)[:, None]
    write_span(d / "span.txt", t, p)
    write_csv(d / "truth.csv", t, p, "week-geodetic")
    (d / "tiny.ubx").write_bytes(_ubx_frames())
    rng = np.random.default_rng(0)
    rows = ["t_s,err_n_m,err_e_m,err_d_m,h_acc_m,v_acc_m"]
    for k in range(100):
        e = rng.normal(0.0, 3.0, 3)
        rows.append(f"{0.2 * k:.1f},{e[0]:.3f},{e[1]:.3f},{e[2]:.3f},{abs(e[0]) + 2:.2f},{abs(e[2]) + 3:.2f}")
    (d / "series.csv").write_text("\n".join(rows) + "\n")
    write_flight(d / "ansfl", seconds=8.0)
    _head_with_rinex(d)
    return {"head": d / "head.tlog", "head_obs": d / "head.obs", "head_nav": d / "head.nav",
            "obs2": obs2, "nav2g": nav2g, "nav2r": nav2r, "nav4": d / "v4.rnx", "drive": drive, "gt": gt,
            "span": d / "span.txt", "truth_csv": d / "truth.csv", "ubx": d / "tiny.ubx",
            "series": d / "series.csv", "ansfl": d / "ansfl", "drive_imu": d / "imu_Input.txt"}


def _with_imu_rows(drive: Path, out: Path) -> None:
    """The drive with imu rows (100 Hz, a level IMU z up turning at 0.05 rad/s) instead of its odometry."""
    lines = [ln for ln in drive.read_text().splitlines() if not ln.startswith("odom3")]
    t = []
    for ln in lines:
        parts = ln.split()
        if parts[:1] == ["pseudorange3"] and len(parts) > 1 and parts[1].replace(".", "", 1).isdigit():
            t.append(float(parts[1]))  # (the drive holds one damaged row on purpose)
    lines += [f"imu {k / 100:.2f} 0.01 -0.02 9.81 0.0 0.0 0.05 0 0 0 0 0 0"
              for k in range(int(min(t) * 100), int(max(t) * 100) + 1)]
    out.write_text("\n".join(lines) + "\n")


def _head_with_rinex(d: Path) -> None:
    """quad106's first 300 kB and RINEX files seen from its GPS_RAW_INT positions once a second (as
    test_gnss_replay's ``rinex_for_quad106``, shorter)."""
    import math

    from companion.gnss.geometry import geodetic_to_ecef
    from companion.gnss.timescale import BootTimeMap
    from companion.mavlink.tlog import read_tlog
    from gcs_tools.gnss.rinex import write_nav, write_obs
    from tests.gnss_helpers import constellation, observe, store
    from tests.test_fuzz_inputs import _frames
    from tests.test_gnss_replay import QUAD106, UNIX0_S

    data = QUAD106.read_bytes()[:300_000]
    (d / "head.tlog").write_bytes(data[: _frames(data)[-1][1]])
    tmap = BootTimeMap.from_system_time(np.array([UNIX0_S * 1e6]), np.array([0.0]))
    fixes = [(m.time_usec, m.lat * 1e-7, m.lon * 1e-7, m.alt * 1e-3)
             for _, m in read_tlog(d / "head.tlog", types=("GPS_RAW_INT",)) if m.fix_type >= 3]
    t_mid = tmap.gps_s(fixes[len(fixes) // 2][0])
    st, epochs, last = store(t_mid), [], -1
    for t_us, lat, lon, alt in fixes:
        if t_us // 1_000_000 != last:
            last = t_us // 1_000_000
            p = geodetic_to_ecef(math.radians(lat), math.radians(lon), alt)
            epochs.append(observe(st, tmap.gps_s(t_us), p, atmosphere=False)[0])
    kep, glo = constellation(t_mid)
    write_nav(d / "head.nav", kep, glo)
    write_obs(d / "head.obs", epochs, "GPS", glonass_channels={g.prn: g.channel for g in glo})


def _spp(*args: object) -> Callable[[Path, Path], list[str]]:
    """``gnss spp`` with the damaged file in the place of ``None``."""
    return lambda p, out: [*SPP, *(str(p) if a is None else str(a) for a in args), "--out", str(out)]


# (name, the undamaged file, the command with the damaged one, mutations, text)
CASES: list[tuple[str, Callable[[dict[str, Path]], Path], Any, int, bool]] = [
    ("rinex3_obs", lambda s: OBS, lambda s: _spp(None, "--nav", NAV), 20, True),
    ("rinex3_nav", lambda s: NAV, lambda s: _spp(OBS, "--nav", None), 20, True),
    ("rinex3_real_obs", lambda s: STATION_OBS,
     lambda s: _spp(None, "--nav", REAL_NAV, f"--truth-ecef={STATION_ECEF}"), 12, True),
    ("rinex3_real_nav", lambda s: REAL_NAV,
     lambda s: _spp(STATION_OBS, "--nav", None, f"--truth-ecef={STATION_ECEF}"), 12, True),
    ("rinex2_obs", lambda s: s["obs2"],
     lambda s: _spp(None, "--nav", s["nav2g"], "--nav", s["nav2r"]), 12, True),
    ("rinex2_gps_nav", lambda s: s["nav2g"],
     lambda s: _spp(s["obs2"], "--nav", None, "--nav", s["nav2r"]), 8, True),
    ("rinex2_glonass_nav", lambda s: s["nav2r"],
     lambda s: _spp(s["obs2"], "--nav", s["nav2g"], "--nav", None), 8, True),
    ("rinex4_nav", lambda s: s["nav4"], lambda s: _spp(OBS, "--nav", None), 8, True),
    ("smartloc_input", lambda s: s["drive"], lambda s: _spp(None, "--truth", s["gt"]), 12, True),
    ("smartloc_truth", lambda s: s["gt"], lambda s: _spp(s["drive"], "--truth", None), 12, True),
    ("span_truth", lambda s: s["span"], lambda s: _spp(OBS, "--nav", NAV, "--truth", None), 8, True),
    ("csv_truth", lambda s: s["truth_csv"], lambda s: _spp(OBS, "--nav", NAV, "--truth", None), 8, True),
    ("ubx", lambda s: s["ubx"], lambda s: _spp(None), 12, False),
    ("smartloc_replay_tight", lambda s: s["drive"],
     lambda s: lambda p, out: ["replay", "--smartloc", str(p), "--truth", str(s["gt"]), "--coupling", "tight",
                               "--out", str(out), *REPLAY_FLAGS], 6, True),
    ("smartloc_imu_replay_tight", lambda s: s["drive_imu"],
     lambda s: lambda p, out: ["replay", "--smartloc", str(p), "--truth", str(s["gt"]), "--coupling", "tight",
                               "--out", str(out), *REPLAY_FLAGS], 6, True),
    ("ulog", lambda s: DATA / "sample_px4_events.ulg",
     lambda s: lambda p, out: ["replay", str(p), "--out", str(out), *REPLAY_FLAGS], 8, False),
    ("dataflash", lambda s: DATA / "arducopter_sitl_hover.bin",
     lambda s: lambda p, out: ["replay", str(p), "--out", str(out), *REPLAY_FLAGS], 2, False),
    ("error_series", lambda s: s["series"],
     lambda s: lambda p, out: ["replay", str(s["ansfl"]), "--gnss-errors", str(p), "--out", str(out),
                               *REPLAY_FLAGS], 8, True),
    ("ansfl_imu", lambda s: s["ansfl"] / "IMU_1.csv", lambda s: _ansfl(s, "IMU_1.csv"), 12, True),
    ("ansfl_truth", lambda s: s["ansfl"] / "GT.csv", lambda s: _ansfl(s, "GT.csv"), 12, True),
    ("rinex_replay_tight_obs", lambda s: s["head_obs"], lambda s: _head_replay(s, "obs"), 6, True),
    ("rinex_replay_tight_nav", lambda s: s["head_nav"], lambda s: _head_replay(s, "nav"), 6, True),
]


def _ansfl(s: dict[str, Path], name: str) -> Callable[[Path, Path], list[str]]:
    """``replay FLIGHT --gnss-errors none`` of a copy of the ANSFL flight with ``name`` damaged."""
    def argv(p: Path, out: Path) -> list[str]:
        flight = p.parent / f"{p.stem}_flight"
        flight.mkdir()
        for f in s["ansfl"].iterdir():
            (flight / f.name).write_bytes(p.read_bytes() if f.name == name else f.read_bytes())
        return ["replay", str(flight), "--gnss-errors", "none", "--out", str(out), *REPLAY_FLAGS]
    return argv


def _head_replay(s: dict[str, Path], damaged: str) -> Callable[[Path, Path], list[str]]:
    """``replay HEAD --rinex-obs --rinex-nav --coupling tight`` with the ``damaged`` one (obs, nav)."""
    def argv(p: Path, out: Path) -> list[str]:
        files = {"obs": s["head_obs"], "nav": s["head_nav"], damaged: p}
        return ["replay", str(s["head"]), "--rinex-obs", str(files["obs"]), "--rinex-nav", str(files["nav"]),
                "--coupling", "tight", "--out", str(out), *REPLAY_FLAGS]
    return argv


@pytest.mark.parametrize(("name", "source", "command", "n", "text"), CASES, ids=[c[0] for c in CASES])
def test_damaged_files_end_in_a_result_or_one_line(tmp_path, sources, name, source, command, n, text):
    """Cuts, bit flips, junk, deleted/duplicated/swapped lines, numbers replaced by NaN/inf/huge/negative/
    garbage or moved (time back, jumps), empty, binary junk, UTF-16: exit 0 or one line, exit 2."""
    seed = sum(name.encode())
    rcs = _fuzz(tmp_path, source(sources).read_bytes(), source(sources).suffix,
                lambda p: command(sources)(p, tmp_path / "out"), n, seed, text=text)
    assert rcs.get(2, 0) >= 2  # at least the empty file and the junk are refused


def test_mutated_companion_configs_load_or_fail_in_one_line(tmp_path):
    """packaging/companion.yaml mutated (as the mission files are): the options and the estimator: and
    tight: sections load or are refused in one line (a UserError), nothing else raises."""
    import dataclasses

    from companion.autopilot.service import config_from_args
    from companion.errors import UserError
    from gcs_tools import companion_config
    from gcs_tools.cli import build_parser

    parser = build_parser(["companion"])

    def load(path: Path) -> None:
        args = parser.parse_args(["companion", "--config", str(path)])
        sections = companion_config.merge(args, args._config_parser, args._option_defaults)
        config = config_from_args(args)
        dataclasses.replace(config, estimator=companion_config.estimator_config(sections, args.config),
                            tight=companion_config.tight_config(sections, args.config))

    source = Path(__file__).parents[1] / "packaging" / "companion.yaml"
    load(source)
    outcomes = {"loaded": 0, "refused": 0}
    for name, data in mutations(np.random.default_rng(17), source.read_bytes(), 150):
        path = tmp_path / f"{name}.yaml"
        path.write_bytes(data)
        try:
            load(path)
            outcomes["loaded"] += 1
        except UserError as exc:
            assert str(exc) and "\n" not in str(exc), (name, str(exc))
            outcomes["refused"] += 1
    assert outcomes["refused"] > 40 and sum(outcomes.values()) == 154


def test_rinex_nav_orbit_inside_the_earth_or_open_is_a_bad_record(tmp_path):
    """sqrt(A) 0 (a division by zero) and e 1.5 (NaN satellite positions) were stored as ephemerides:
    their satellites then fell out as non-finite, uncounted. Now each record is a counted bad_record."""
    lines = NAV.read_text().splitlines()
    assert lines[5].startswith("G01") and lines[13].startswith("G02")
    lines[7] = lines[7][:61] + " 0.000000000000D+00"  # G01's sqrt(A)
    lines[15] = lines[15][:23] + " 1.500000000000D+00" + lines[15][42:]  # G02's e
    path = tmp_path / "orbits.nav"
    path.write_text("\n".join(lines) + "\n")
    nav = rinex.read_nav(path)
    assert nav.rejected == {"bad_record": 2}
    assert {e.prn for e in nav.kepler if e.system == 0} == set(range(3, 25))


def test_smartloc_rows_no_satellite_gives_are_counted(tmp_path):
    """A pseudorange3 row with a finite 1e308 satellite coordinate overflowed the solver (RuntimeWarnings,
    a lost epoch, uncounted); such rows (range, satellite distance, variance, C/N0) are counted now."""
    from gcs_tools.gnss import smartloc
    from tests.test_gnss_readers import _write_smartloc

    drive, _ = _write_smartloc(tmp_path)
    good = smartloc.read_input(drive)
    lines = drive.read_text().splitlines()
    rows = [i for i, line in enumerate(lines) if line.startswith("pseudorange3 0.2 ")]
    for i, (k, bad) in zip(rows, [(4, "1e308"), (2, "3e8"), (10, "-3552"), (3, "-1")], strict=False):
        parts = lines[i].split()
        parts[k] = bad
        lines[i] = " ".join(parts)
    drive.write_text("\n".join(lines) + "\n")
    got = smartloc.read_input(drive)
    assert got.rejected - good.rejected == {"out_of_range": 4}
    assert sum(e.n for e in good.epochs) - sum(e.n for e in got.epochs) == 4
