"""``beliefnav replay`` of ArduPilot DataFlash ``.bin`` and PX4 ``.ulg`` logs, against the
autopilot's own logged estimate and truth; damaged logs; streaming; concatenated logs."""

from __future__ import annotations

import json
import math
import os
import threading
from pathlib import Path

import numpy as np
import pytest
from pymavlink import DFReader

from companion.domain.samples import AttitudeSample, GnssFix, ImuSample
from companion.errors import UserError
from companion.mavlink import codec as mc
from companion.mavlink import tlog as tlog_module
from companion.mavlink.tlog import TlogReader, TlogWriter
from gcs_tools.cli import main
from gcs_tools.replay import core, dataflash
from gcs_tools.replay import ulog as ulog_module
from gcs_tools.replay.dataflash import DataFlashScanner, DataFlashSource
from gcs_tools.replay.events import ReaderStats
from gcs_tools.replay.logs import detect_format, open_log

DATA = Path(__file__).parent / "data"
SITL_BIN = DATA / "arducopter_sitl_hover.bin"
PX4_NEW = DATA / "sample_px4_events.ulg"
PX4_OLD = DATA / "sample_logging_tagged_and_default_params.ulg"
QUAD106 = DATA / "quad106.tlog"


@pytest.fixture(scope="module")
def sitl_replay() -> core.ReplayResult:
    return core.replay(SITL_BIN, "second-order")


def test_formats_are_recognised_by_content_then_extension(tmp_path: Path) -> None:
    assert detect_format(SITL_BIN) == "dataflash" and detect_format(PX4_NEW) == "ulog"
    assert detect_format(QUAD106) == "tlog"
    renamed = tmp_path / "flight.tlog"
    renamed.write_bytes(SITL_BIN.read_bytes()[:4096])
    assert detect_format(renamed) == "dataflash"  # the FMT header wins over the name


def test_dataflash_reader_equals_pymavlink_dfreader() -> None:
    """Every IMU (instance 0), ATT and GPS value the streaming reader yields is the one
    pymavlink's DFReader decodes from the same log (exact equivalence, same order)."""
    ref: dict[str, list[tuple[float, ...]]] = {"IMU": [], "ATT": [], "GPS": []}
    log = DFReader.DFReader_binary(str(SITL_BIN), zero_time_base=False)
    while (m := log.recv_msg()) is not None:
        kind = m.get_type()
        if kind in ref and getattr(m, "I", 0) == 0:
            ref[kind].append(tuple(float(getattr(m, f.names[0])) for f in dataflash.FIELDS[kind]))
    ours: dict[str, list[tuple[float, ...]]] = {"IMU": [], "ATT": [], "GPS": []}
    for name, values in DataFlashScanner(SITL_BIN, ref, ReaderStats()):
        ours[name].append(tuple(float(v) for v in values))
    assert len(ref["IMU"]) > 10_000 and len(ref["GPS"]) > 300 and len(ref["ATT"]) > 500
    assert ours == ref


def test_dataflash_samples_units_frames_and_fix_validity() -> None:
    src = DataFlashSource(SITL_BIN)
    events = list(src)
    imu = [e for e in events if type(e) is ImuSample]
    att = [e for e in events if type(e) is AttitudeSample]
    fixes = [e for e in events if type(e) is GnssFix and e.fix_type >= 3]
    acc = np.array([s.acc_frd_m_s2 for s in imu[:100]])  # on the ground, level: specific force up
    assert np.allclose(acc.mean(axis=0), [0.0, 0.0, -9.81], atol=0.05)
    q = att[0].q_ned_frd
    assert abs(np.linalg.norm(q) - 1) < 1e-9 and abs(q[0]) > 0.99  # yaw ~0 in ATT at boot
    assert src.gps_delay_ms == dataflash.DEFAULT_GPS_DELAY_MS  # GPS1_DELAY_MS is 0 in this log
    # validity = GPA.SMS (ms of reception) - delay: on a whole millisecond minus 120 ms, but
    # for the few GPS without their GPA (then GPS.TimeUS - delay)
    off_ms = sum((f.t_validity_us + 120_000) % 1000 != 0 for f in fixes)
    assert src.stats.decoded["gnss"] == 369 and src.stats.decoded["gnss_without_gpa"] == 4
    assert len(fixes) > 360 and off_ms <= 4
    assert src.references["autopilot_estimate"].source == "POS"
    assert src.references["truth"].source == "SIM"


def test_sitl_bin_against_ekf_and_truth(sitl_replay: core.ReplayResult) -> None:
    """The SITL flight (ground, take-off to 10 m, hover, land; noise-free SITL GPS): the
    estimate stays within centimetres of ArduPilot's EKF3 position (POS) and of SIM truth."""
    s = sitl_replay.summary
    assert s["format"] == "dataflash" and s["log_restarts"] == 0
    ap, truth = s["errors"]["autopilot_estimate"], s["errors"]["truth"]
    assert ap["alignment"] == "geodetic" and ap["offset_ned_m"] == [0.0, 0.0, 0.0]
    assert ap["n"] > 1500 and truth["n"] > 1500
    assert ap["error_horizontal_m"]["median"] < 0.05 and ap["error_horizontal_m"]["max"] < 0.3
    assert ap["error_3d_m"]["median"] < 0.1 and ap["error_3d_m"]["p95"] < 0.3
    assert truth["error_horizontal_m"]["median"] < 0.05 and truth["error_3d_m"]["p95"] < 0.3
    # the flight really climbed ~10 m (the comparison is not of a vehicle standing still)
    p_d = sitl_replay.table[:, 2]
    assert p_d.min() < -8.0
    nav = s["navigator"]
    assert nav["gnss_fused"] > 350 and nav["imu_used"] > 15_000


@pytest.mark.parametrize(("log", "autopilot_topic", "truth"), [
    (PX4_NEW, "vehicle_global_position", None),
    (PX4_OLD, "vehicle_local_position", "vehicle_global_position_groundtruth"),
])
def test_px4_ulogs_against_px4_estimate_and_truth(log: Path, autopilot_topic: str, truth: str | None) -> None:
    """Both PX4 releases' field names; EKF2's estimate within decimetres (hover in SITL)."""
    s = core.replay(log, "second-order").summary
    assert s["format"] == "ulog"
    ap = s["errors"]["autopilot_estimate"]
    assert ap["source"] == autopilot_topic and ap["alignment"] == "geodetic" and ap["n"] > 50
    assert ap["error_horizontal_m"]["median"] < 0.1 and ap["error_3d_m"]["median"] < 0.2
    assert ap["error_3d_m"]["max"] < 1.0
    assert s["gnss_validity"]["gps_delay_ms"] == 110.0  # EKF2_GPS_DELAY: no timestamp_sample logged
    if truth is None:
        assert "truth" not in s["errors"]
    else:
        t = s["errors"]["truth"]
        assert t["source"] == truth and t["alignment"] == "vertical_mean_offset" and t["n"] >= 10
        assert abs(t["offset_ned_m"][2] + 488.0) < 1.0  # PX4 SITL logs the truth's altitude as 0
        assert t["error_horizontal_m"]["median"] < 0.1 and t["error_3d_m"]["max"] < 0.2


def test_ulog_missing_topic_and_field_are_one_line_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = PX4_NEW.read_bytes()
    no_gps = tmp_path / "no_gps.ulg"
    no_gps.write_bytes(data.replace(b"vehicle_gps_position", b"vehicle_gps_positioN"))
    no_field = tmp_path / "no_field.ulg"
    no_field.write_bytes(data.replace(b"latitude_deg", b"latitude_deX"))
    for path, words in ((no_gps, ("no topic vehicle_gps_position",)), (no_field, ("vehicle_gps_position",
                                                                                  "latitude_deg or lat"))):
        assert main(["replay", str(path), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("beliefnav: error: ") and "\n" not in err
        assert all(w in err for w in words), err


def test_dataflash_missing_field_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "renamed.bin"
    bad.write_bytes(SITL_BIN.read_bytes().replace(b"TimeUS,I,GyrX,", b"TimeUS,I,GyrQ,"))
    assert main(["replay", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "IMU has no field GyrX" in err and "\n" not in err


def test_damaged_dataflash_is_read_around_the_damage(tmp_path: Path) -> None:
    """Garbage in the middle is skipped and counted; a cut end is counted as truncated; every
    intact message is still read."""
    data = SITL_BIN.read_bytes()
    cut = len(data) // 2
    bad = tmp_path / "damaged.bin"
    bad.write_bytes(data[:cut] + bytes(range(7, 7 + 200)) + data[cut:-10])
    whole, damaged = ReaderStats(), ReaderStats()
    n_whole = sum(1 for _ in DataFlashScanner(SITL_BIN, dataflash.FIELDS, whole))
    n_damaged = sum(1 for _ in DataFlashScanner(bad, dataflash.FIELDS, damaged))
    assert damaged.skipped["garbage"] >= 1 and damaged.skipped["truncated"] == 1
    assert 0 <= whole.records - damaged.records <= 2 and 0 <= n_whole - n_damaged <= 2
    s = core.replay(bad, "second-order").summary
    assert s["samples_rejected"]["reader"]["truncated"] == 1 and s["errors"]["autopilot_estimate"]["n"] > 1500


@pytest.mark.parametrize(("content", "reason"), [
    (lambda d: d[:5000], "no usable GPS 3-D fix"),
    (lambda d: b"\xa3\x95\x80" + bytes(300), "no usable GPS 3-D fix (Status >= 3) in 0 GPS of 1 messages"),
    (lambda d: np.random.default_rng(3).integers(0, 256, 5000, dtype=np.uint8).tobytes(),
     "no readable DataFlash messages"),
])
def test_unusable_dataflash_is_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                content: object, reason: str) -> None:
    bad = tmp_path / "bad.bin"
    bad.write_bytes(content(SITL_BIN.read_bytes()))  # type: ignore[operator]
    assert main(["replay", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("beliefnav: error: ") and reason in err and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_truncated_ulog_is_a_one_line_error_or_a_shorter_replay(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    data = PX4_NEW.read_bytes()
    for size in (10, 3000, len(data) // 2):
        bad = tmp_path / f"cut{size}.ulg"
        bad.write_bytes(data[:size])
        code = main(["replay", str(bad), "--out", str(tmp_path / f"o{size}")])
        err = capsys.readouterr().err.strip()
        assert code in (0, 2) and (code == 0 or (err.startswith("beliefnav: error: ") and "\n" not in err))
    assert code == 0  # half the log still replays


def test_ulog_cut_inside_its_definitions_says_so_on_stderr_only(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """pyulog prints what it finds damaged on stdout: kept off it (stdout is the --json document) and
    named in the one-line error instead of a bare 'no topic'."""
    bad = tmp_path / "cut20.ulg"
    bad.write_bytes(PX4_NEW.read_bytes()[:20])
    assert main(["replay", str(bad), "--out", str(tmp_path / "o"), "--json"]) == 2
    printed = capsys.readouterr()
    assert printed.out == ""
    err = printed.err.strip()
    assert err.startswith("beliefnav: error: ") and "\n" not in err
    assert "has no topic vehicle_gps_position (its definitions section is damaged: pyulog: " in err


def test_out_naming_a_file_is_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "file"
    f.write_text("x")
    assert main(["replay", str(SITL_BIN), "--out", str(f)]) == 2
    assert "exists and is not a directory" in capsys.readouterr().err
    assert main(["replay", str(PX4_NEW), "--out", str(tmp_path / "o"), "--gps-delay-ms", "50"]) == 2
    assert "--gps-delay-ms applies to DataFlash" in capsys.readouterr().err


def test_gps_delay_option_moves_every_validity_time() -> None:
    a = [e.t_validity_us for e in DataFlashSource(SITL_BIN) if type(e) is GnssFix]
    b = [e.t_validity_us for e in DataFlashSource(SITL_BIN, gps_delay_ms=50.0) if type(e) is GnssFix]
    assert len(a) == len(b) > 300 and all(x + 70_000 == y for x, y in zip(a, b, strict=True))


# --- streaming --------------------------------------------------------------------------------


def _fifo_feed(fifo: Path, chunks: list[bytes], consumed: list[threading.Event]) -> threading.Thread:
    """Write ``chunks`` into a FIFO, each only after the reader has consumed the previous one."""
    def writer() -> None:
        with open(fifo, "wb") as f:
            for k, chunk in enumerate(chunks):
                if k and not consumed[k - 1].wait(60):
                    return  # the reader did not stream: it waited for the end of the file
                f.write(chunk)
                f.flush()
    t = threading.Thread(target=writer, daemon=True)
    t.start()
    return t


@pytest.mark.parametrize("kind", ["tlog", "dataflash"])
def test_readers_stream_the_file(tmp_path: Path, kind: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A log fed through a pipe, its second half written only after the reader has yielded
    messages from the first half: a reader that read the whole file first would never get there."""
    monkeypatch.setattr(tlog_module, "READ_BLOCK", 4096)
    monkeypatch.setattr(dataflash, "READ_BLOCK", 4096)
    data = (QUAD106 if kind == "tlog" else SITL_BIN).read_bytes()[:600_000]
    half = 300_000
    fifo = tmp_path / "log.fifo"
    os.mkfifo(fifo)
    consumed = [threading.Event()]
    writer = _fifo_feed(fifo, [data[:half], data[half:]], consumed)
    count = 0
    items = (TlogReader(fifo) if kind == "tlog" else DataFlashScanner(fifo, dataflash.FIELDS, ReaderStats()))
    for _ in items:
        count += 1
        if count == 1000:
            consumed[0].set()
    writer.join(5)
    assert count > 2000 and consumed[0].is_set()


@pytest.mark.parametrize("log", [QUAD106, SITL_BIN, PX4_NEW])
def test_every_reader_yields_before_it_has_read_the_file(log: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A generator over the file: after the first 2000 events, less than half of the
    file has been read (the ULog reader's definitions are read first, then data in batches)."""
    monkeypatch.setattr(tlog_module, "READ_BLOCK", 4096)
    monkeypatch.setattr(dataflash, "READ_BLOCK", 4096)
    monkeypatch.setattr(ulog_module, "BATCH", 256)
    reader = open_log(log)
    events = iter(reader)
    for _ in range(2000):
        next(events)
    assert 0 < reader.stats.position < reader.stats.size / 2, (reader.stats.position, reader.stats.size)
    rest = sum(1 for _ in events)
    assert rest > 5000 and reader.stats.position == reader.stats.size


def test_block_boundaries_change_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Reading in tiny blocks yields exactly what whole-file reading does, damage included."""
    data = bytearray(QUAD106.read_bytes()[:200_000])
    data[50_000:50_040] = bytes(40)  # a damaged span
    log = tmp_path / "damaged.tlog"
    log.write_bytes(bytes(data[:-7]))  # and a cut end

    def read() -> tuple[list[tuple[int, tuple[object, ...]]], dict[str, int], int, int]:
        r = TlogReader(log)
        out = [(t, tuple(v)) for t, v in r]
        return out, dict(r.skipped), r.skipped_bytes, r.frames

    big = read()
    monkeypatch.setattr(tlog_module, "READ_BLOCK", 333)
    assert read() == big and big[1] and len(big[0]) > 1000


def test_estimates_are_written_while_replaying(tmp_path: Path) -> None:
    out = tmp_path / "out"
    csv = out / "estimates.csv"
    seen: list[int] = []

    def on_imu(t_us: int, nav: object) -> None:
        if csv.exists():
            seen.append(csv.stat().st_size)

    result = core.replay(SITL_BIN, "second-order", out_dir=out, on_imu=on_imu)
    assert result.table.shape[0] == 0  # nothing kept in memory
    assert len(set(seen)) > 5 and max(seen) < csv.stat().st_size  # the file grew during the replay
    rows = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert rows.shape == (result.summary["estimates"], len(core.CSV_COLUMNS))


# --- concatenated logs and restarts -----------------------------------------------------------


def test_concatenated_log_is_replayed_as_segments_with_the_navigators_counters(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Three copies of a 60 s tlog: two restarts, and each segment exactly the single replay."""
    one = tmp_path / "one.tlog"
    one.write_bytes(QUAD106.read_bytes()[:400_000])
    three = tmp_path / "three.tlog"
    three.write_bytes(one.read_bytes() * 3)
    single = core.replay(one, "second-order", rate_hz=0)
    triple = core.replay(three, "second-order", rate_hz=0)
    s1, s3 = single.summary, triple.summary
    assert s1["log_restarts"] == 0 and s3["log_restarts"] == 2 and len(s3["segments"]) == 3
    assert {k: 3 * v for k, v in s1["navigator"].items()} == s3["navigator"]
    assert s3["navigator"].get("imu_rejected_time_backwards", 0) == 0
    n = single.t_us.size
    assert triple.t_us.size == 3 * n
    for k in range(3):
        assert np.array_equal(triple.t_us[k * n:(k + 1) * n], single.t_us)
        assert np.array_equal(triple.table[k * n:(k + 1) * n, :-1], single.table[:, :-1], equal_nan=True)
        assert (triple.table[k * n:(k + 1) * n, -1] == k).all()  # the segment column
    assert s3["errors"]["gnss"]["n"] == 3 * s1["errors"]["gnss"]["n"]
    assert s3["duration_s"] == pytest.approx(3 * s1["duration_s"])
    # the printed counters are the navigators'
    assert main(["replay", str(three), "--out", str(tmp_path / "o"), "--no-progress", "--no-figures"]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert f"IMU samples used {summary['navigator']['imu_used']:,}," in printed
    assert "2 log restart(s)" in printed


def _log_with_a_stray_imu_sample(tmp_path: Path, stamp_us: int) -> tuple[Path, Path]:
    """The first 400 kB of quad106 (plain) and the same with one IMU sample stamped ``stamp_us``
    inserted in the middle."""
    plain = tmp_path / "plain.tlog"
    plain.write_bytes(QUAD106.read_bytes()[:400_000])
    reader = TlogReader(plain)
    mid = next(reader.position for _ in reader if reader.position > 200_000)
    stray = tmp_path / "stray.tlog"
    with TlogWriter(stray) as w:
        w.write(0, mc.encode_imu(ImuSample(stamp_us, np.array([0.0, 0, -9.8]), np.zeros(3))))
    data = plain.read_bytes()
    log = tmp_path / "outlier.tlog"
    log.write_bytes(data[:mid] + stray.read_bytes() + data[mid:])
    return plain, log


def test_a_lone_sample_far_back_is_not_a_restart(tmp_path: Path) -> None:
    """One IMU sample stamped 1 ms after boot in the middle of a 60 s log: counted by the
    navigator as time going backwards, no new segment, every other sample used as before."""
    plain, log = _log_with_a_stray_imu_sample(tmp_path, 1000)
    s = core.replay(log, "second-order").summary
    base = core.replay(plain, "second-order").summary
    assert s["log_restarts"] == 0 and s["navigator"]["imu_rejected_time_backwards"] == 1
    assert s["navigator"]["imu_used"] == base["navigator"]["imu_used"]


@pytest.mark.parametrize("stamp_us", [1_500_000_000_000_000_000, 1_000_000_000_000])
def test_a_lone_sample_far_ahead_is_dropped_and_counted(tmp_path: Path, stamp_us: int) -> None:
    """One IMU sample stamped decades (or days) ahead in the middle of a 60 s log, as a
    damaged stamp: dropped and counted (imu_time_jump), the time base not moved, so every other
    sample is used as in the undamaged log (it used to be fused, and every later sample was then
    refused as time going backwards)."""
    plain, log = _log_with_a_stray_imu_sample(tmp_path, stamp_us)
    s = core.replay(log, "second-order").summary
    base = core.replay(plain, "second-order").summary
    assert s["log_restarts"] == 0
    assert s["navigator"]["imu_used"] == base["navigator"]["imu_used"]
    assert s["navigator"].get("imu_rejected_time_backwards", 0) == base["navigator"].get(
        "imu_rejected_time_backwards", 0)
    assert s["samples_rejected"]["codec"]["imu_time_jump"] == 1


def test_every_format_gives_the_same_summary_blocks(sitl_replay: core.ReplayResult) -> None:
    for s in (sitl_replay.summary, core.replay(PX4_NEW, "naive").summary):
        block = s["errors"]["autopilot_estimate"]
        keys = {"n", "alignment", "offset_ned_m", "error_horizontal_m", "error_3d_m", "source", "note"}
        assert keys <= set(block)
        assert {"median", "p95", "max"} <= set(block["error_horizontal_m"]) and math.isfinite(
            block["error_3d_m"]["median"])


def test_bad_ulog_bytes_are_a_user_error(tmp_path: Path) -> None:
    bad = tmp_path / "x.ulg"
    bad.write_bytes(b"ULog\x01\x12\x35" + bytes(50))
    with pytest.raises(UserError):
        core.replay(bad, "naive")


def test_an_unreadable_optional_message_is_counted_not_fatal(tmp_path: Path) -> None:
    """POS without its Lat field: the replay runs, the reason is counted, and the autopilot's
    estimate comes from EKF3 core 0 (XKF1 about the ORGN origin) instead, as close as POS."""
    log = tmp_path / "no_pos_lat.bin"
    data = SITL_BIN.read_bytes()
    assert data.count(b"TimeUS,Lat,Lng,Alt,RelHomeAlt") == 1
    log.write_bytes(data.replace(b"TimeUS,Lat,Lng,Alt,RelHomeAlt", b"TimeUS,LaX,Lng,Alt,RelHomeAlt"))
    s = core.replay(log, "naive").summary
    assert s["samples_rejected"]["codec"]["pos_unknown_layout"] == 1
    ap = s["errors"]["autopilot_estimate"]
    assert ap["source"] == "XKF1+ORGN" and ap["alignment"] == "geodetic" and ap["n"] > 1500
    assert ap["error_horizontal_m"]["median"] < 0.05 and ap["error_3d_m"]["p95"] < 0.3
    assert s["errors"]["truth"]["n"] > 1500


def test_damaged_ulog_is_read_around_the_damage(tmp_path: Path) -> None:
    """Bytes overwritten in the ULog data section: counted as skipped, the replay still runs on
    what is readable (to the next sync message, or to the damage when there is none)."""
    data = bytearray(PX4_NEW.read_bytes())
    at = int(len(data) * 0.8)
    data[at:at + 64] = b"\xee" * 64
    bad = tmp_path / "damaged.ulg"
    bad.write_bytes(bytes(data))
    s = core.replay(bad, "second-order").summary
    whole = core.replay(PX4_NEW, "second-order").summary
    skipped = s["samples_rejected"]
    assert sum(skipped["reader"].values()) >= 1 and skipped["reader_skipped_bytes"] > 0
    assert 0.5 * whole["samples_used"]["imu"] < s["samples_used"]["imu"] <= whole["samples_used"]["imu"]


def test_out_below_a_file_is_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "file"
    f.write_text("x")
    assert main(["replay", str(SITL_BIN), "--out", str(f / "sub")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("beliefnav: error: --out ") and "cannot write estimates.csv" in err
    assert "\n" not in err
