"""Fuzz the file readers (seeded): RINEX observation and navigation files, smartLoc drives, UBX logs,
DataFlash and ULog logs, error series, truth files and the companion's config, through the real
commands. Each damaged file ends in a result (exit 0, the damage counted) or in one line (exit 2);
never a traceback, never a hang. And the regressions those mutations found, as known answers."""

from __future__ import annotations

import contextlib
import io
from collections.abc import Callable
from pathlib import Path

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
    names = ["timestamp", *(f"gyro_rad[{i}]" for i in range(3)), *(f"accelerometer_m_s2[{i}]" for i in range(3))]
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
