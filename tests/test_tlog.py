"""tlog writer and fast reader: mavlogdump reads what we write, we read what pymavlink reads,
and damaged files are read as far as they are readable with every skip counted."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.domain.samples import AttitudeSample, GnssFix, ImuSample, NavEstimate
from companion.mavlink import codec as mc
from companion.mavlink.tlog import TlogWriter, read_tlog

DATA = Path(__file__).parent / "data"
QUAD106 = DATA / "quad106.tlog"
N_TICKS = 60
T0_UNIX_US = 1_700_000_000_000_000


def _messages(k: int) -> list:
    t_us = 1_000_000 + 5_000 * k
    msgs = [
        mc.encode_imu(ImuSample(t_us, np.array([0.01 * k, 0.0, -9.81]), np.array([0.0, 0.001 * k, 0.0]))),
        mc.encode_attitude(AttitudeSample(t_us, np.array([1.0, 0.0, 0.0, 0.0]))),
    ]
    if k % 4 == 0:
        msgs.append(mc.encode_gnss(GnssFix(t_us - 200_000, -37.86 + 1e-6 * k, 144.76, 10.0, 3, 12)))
    if k % 20 == 0:
        p = np.full(3, 0.5 * k)
        est = NavEstimate(t_us, p, np.ones(3), np.zeros(3), np.full(9, 0.25), 0.75, 2.0, "naive")
        msgs += [mc.encode_heartbeat("vehicle"), mc.encode_odometry(est), *mc.encode_belief(est)]
    return msgs


@pytest.fixture
def small_tlog(tmp_path: Path) -> tuple[Path, list[int], list[tuple[int, str]]]:
    """A synthetic tlog; returns its path, the byte offset where each frame ends, (stamp, type)."""
    path = tmp_path / "small.tlog"
    ends, expected = [], []
    with TlogWriter(path) as w:
        for k in range(N_TICKS):
            for msg in _messages(k):
                stamp = T0_UNIX_US + 5_000 * k
                w.write(stamp, msg)
                w.flush()
                ends.append(path.stat().st_size)
                expected.append((stamp, msg.get_type()))
    return path, ends, expected


def _read(path: Path, types=None):
    reader = read_tlog(path, types)
    out = [(stamp, m) for stamp, m in reader]
    return reader, out


def test_round_trip_and_type_filter(small_tlog) -> None:
    path, _, expected = small_tlog
    reader, out = _read(path)
    assert [(s, m.get_type()) for s, m in out] == expected
    assert not reader.skipped and reader.frames == len(expected)
    imu = [mc.decode_sample(m) for _, m in out if m.get_type() == "HIGHRES_IMU"]
    assert imu[7].acc_frd_m_s2[0] == pytest.approx(0.07, rel=1e-6)
    odometry = [mc.decode_odometry(m) for _, m in out if m.get_type() == "ODOMETRY"]
    assert odometry[2].p_ned_m.tolist() == [20.0] * 3 and odometry[2].cov_diag[5] == 0.25
    named = [mc.decode_named_value(m) for _, m in out if m.get_type() == "NAMED_VALUE_FLOAT"]
    assert [(v.name, v.value) for v in named[:2]] == [("GNSS_BETA", 0.75), ("GNSS_NIS", 2.0)]
    reader, out = _read(path, ["GPS_RAW_INT"])
    assert len(out) == N_TICKS // 4 and reader.frames == len(expected)
    assert mc.decode_sample(out[1][1]).lat_deg == pytest.approx(-37.86 + 4e-6, abs=1e-7)


def test_mavlogdump_reads_our_tlog(small_tlog) -> None:
    path, _, expected = small_tlog
    env = {**os.environ, "MAVLINK20": "1"}
    dump = Path(sys.executable).parent / "mavlogdump.py"
    out = subprocess.run(
        [sys.executable, str(dump), "--types", "GPS_RAW_INT", str(path)],
        capture_output=True, text=True, timeout=60, env=env, check=True,
    ).stdout
    lines = [line for line in out.splitlines() if "GPS_RAW_INT" in line]
    assert len(lines) == sum(t == "GPS_RAW_INT" for _, t in expected)
    assert "lat : -378600000" in lines[0] and "fix_type : 3" in lines[0]


def test_fast_reader_equals_pymavlink_on_the_real_log() -> None:
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(QUAD106))
    ours = read_tlog(QUAD106)
    for (stamp, view), _ in zip(ours, range(4000), strict=False):
        ref = conn.recv_match()
        assert ref.get_type() == view.get_type()
        assert stamp == round(ref._timestamp * 1e6)
        for name in ref.get_fieldnames():
            got, want = getattr(view, name), getattr(ref, name)
            assert list(got) == list(want) if isinstance(got, tuple) else got == want, name


def test_real_log_counts() -> None:
    reader, out = _read(QUAD106, ["HIGHRES_IMU", "ATTITUDE_QUATERNION", "GPS_RAW_INT"])
    kinds = {k: sum(1 for _ in g) for k, g in itertools.groupby(sorted(m.get_type() for _, m in out))}
    assert kinds == {"HIGHRES_IMU": 32936, "ATTITUDE_QUATERNION": 32936, "GPS_RAW_INT": 3339}
    assert reader.frames == 70549 and not reader.skipped


def test_truncated_mid_frame(small_tlog, tmp_path: Path) -> None:
    path, ends, expected = small_tlog
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(path.read_bytes()[: ends[-2] + 11])  # last frame cut inside its header
    reader, out = _read(cut)
    assert len(out) == len(expected) - 1
    assert reader.skipped == {"truncated": 1} and reader.skipped_bytes == 11


def test_bad_crc_skips_one_frame(small_tlog, tmp_path: Path) -> None:
    path, ends, expected = small_tlog
    data = bytearray(path.read_bytes())
    data[ends[9] + 8 + 12] ^= 0x5A  # a payload byte of frame 10
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(bytes(data))
    reader, out = _read(bad)
    assert [(s, m.get_type()) for s, m in out] == expected[:10] + expected[11:]
    assert reader.skipped == {"bad_crc": 1} and reader.skipped_bytes == ends[10] - ends[9]


def test_corrupt_length_byte_loses_one_frame(small_tlog, tmp_path: Path) -> None:
    path, ends, expected = small_tlog
    data = bytearray(path.read_bytes())
    data[ends[4] + 9] = 255  # length byte of frame 5
    bad = tmp_path / "len.tlog"
    bad.write_bytes(bytes(data))
    reader, out = _read(bad)
    assert len(out) == len(expected) - 1 and sum(reader.skipped.values()) == 1


def test_garbage_between_frames(small_tlog, tmp_path: Path) -> None:
    path, ends, expected = small_tlog
    data = path.read_bytes()
    junk = bytes(np.random.default_rng(3).integers(0, 256, 300, dtype=np.uint8)) + b"\xfd\x09\xfe" * 5
    messy = tmp_path / "messy.tlog"
    messy.write_bytes(data[: ends[20]] + junk + data[ends[20] :])
    reader, out = _read(messy)
    assert [(s, m.get_type()) for s, m in out] == expected
    assert sum(reader.skipped.values()) == 1 and reader.skipped_bytes == len(junk)


def test_empty_and_missing_files(tmp_path: Path) -> None:
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    reader, out = _read(empty)
    assert out == [] and not reader.skipped
    with pytest.raises(FileNotFoundError):
        read_tlog(tmp_path / "nope.tlog")
