"""`beliefnav export`: MCAP read back with the `mcap` library and CSV, from a run, a tlog, a recording."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from companion.domain.samples import GnssFix, NavEstimate, TruthState
from companion.mission import load_mission
from companion.telemetry import codec as zc
from gcs_tools.cli import main

QUAD106 = Path(__file__).parent / "data" / "quad106.tlog"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """One in-process flight of the small test mission (its outputs, as `beliefnav fly` writes them)."""
    from gcs_tools.fly.output import write_outputs
    from simvehicle.harness.fly import fly

    mission = load_mission("test")
    out = tmp_path_factory.mktemp("fly")
    write_outputs(fly(mission, 0, "second-order", 3), mission.world, out)
    return out


def _read(path: Path) -> tuple[dict[str, tuple[str, str, str]], dict[str, list[tuple[int, dict]]]]:
    """(topic -> (schema name, schema encoding, message encoding), topic -> [(log_time_ns, message)])."""
    channels: dict[str, tuple[str, str, str]] = {}
    messages: dict[str, list[tuple[int, dict]]] = {}
    with path.open("rb") as f:
        for schema, channel, msg in make_reader(f).iter_messages(log_time_order=False):
            channels[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
            messages.setdefault(channel.topic, []).append((msg.log_time, json.loads(msg.data)))
    return channels, messages


def _csv(path: Path) -> dict[str, np.ndarray]:
    table = np.genfromtxt(path, delimiter=",", names=True)
    return {n: table[n] for n in table.dtype.names}


def test_run_directory_to_mcap_has_foxglove_schemas_and_the_flight(run_dir, tmp_path):
    out = tmp_path / "run.mcap"
    assert main(["export", str(run_dir), "--out", str(out)]) == 0
    channels, msgs = _read(out)
    assert channels["/pose/true"] == ("foxglove.PoseInFrame", "jsonschema", "json")
    assert channels["/path/estimated"] == ("foxglove.PosesInFrame", "jsonschema", "json")
    assert channels["/map/true"][0] == "foxglove.LocationFix"
    assert channels["/beliefnav/state"][0] == "beliefnav.State"
    ts = _csv(run_dir / "timeseries.csv")
    n = len(ts["t_s"])
    state = msgs["/beliefnav/state"]
    assert len(state) == n == len(msgs["/pose/true"])
    # known answers: values as written in timeseries.csv, NaN -> null, time in ns
    for i in (0, n // 2, n - 1):
        log_ns, st = state[i]
        assert log_ns == round(ts["t_s"][i] * 1e9)
        for col in ("beta", "nis", "est_error_m", "track_error_m", "b_est_n_m", "latency_s"):
            v = ts[col][i]
            assert (st[col] is None) if math.isnan(v) else st[col] == v, col
    # poses in ENU: x = east, y = north, z = up
    _, pose = msgs["/pose/true"][n // 2]
    p = pose["pose"]["position"]
    mid = n // 2
    assert (p["x"], p["y"], p["z"]) == (ts["p_true_e_m"][mid], ts["p_true_n_m"][mid], -ts["p_true_d_m"][mid])
    assert pose["timestamp"]["sec"] * 10**9 + pose["timestamp"]["nsec"] == round(ts["t_s"][n // 2] * 1e9)
    (t_path, path), = msgs["/path/true"]
    assert t_path == state[0][0] and len(path["poses"]) == n
    # the map track is the true track in WGS-84 about the mission's home (round trip to < 1 mm)
    frame = load_mission("test").frame
    _, fix = msgs["/map/true"][n // 2]
    back = frame.to_ned_m(fix["latitude"], fix["longitude"], fix["altitude"])
    want = [ts[f"p_true_{a}_m"][n // 2] for a in "ned"]
    assert np.allclose(back, want, atol=1e-3)


def test_run_directory_to_csv_equals_timeseries(run_dir, tmp_path):
    out = tmp_path / "run.csv"
    assert main(["export", str(run_dir), "--format", "csv", "--out", str(out)]) == 0
    a, b = _csv(run_dir / "timeseries.csv"), _csv(out)
    assert set(a) < set(b)  # plus the (here empty) gnss and autopilot tracks
    for col in a:
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)
    assert np.isnan(b["p_gnss_n_m"]).all()


def test_real_tlog_exports_every_fix(tmp_path, capsys):
    out = tmp_path / "q.mcap"
    assert main(["export", str(QUAD106), "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["messages"]["/gnss/fix"] == 3339  # every GPS_RAW_INT of the log is a 3-D fix
    channels, msgs = _read(out)
    assert channels["/gnss/fix"][0] == "foxglove.LocationFix"
    from companion.mavlink import codec
    from companion.mavlink.tlog import read_tlog

    first = codec.decode_gnss(next(m for _, m in read_tlog(QUAD106, ["GPS_RAW_INT"])))
    _, fix0 = msgs["/gnss/fix"][0]
    assert (fix0["latitude"], fix0["longitude"]) == (first.lat_deg, first.lon_deg)
    _, pose0 = msgs["/pose/gnss"][0]  # home = the first fix: the first GNSS pose is the origin
    assert all(abs(v) < 1e-6 for v in pose0["pose"]["position"].values())
    assert "/pose/estimated" not in channels  # the log has no onboard estimate: nothing made up


def _line(vehicle: str, process: str, topic: str, obj) -> str:
    payload = json.loads(zc.encode(topic, obj, 0))
    return json.dumps({"key": zc.key_for(vehicle, process, topic), "recv_unix_ns": 0, "payload": payload})


def test_recording_exports_estimates_truth_and_fixes(tmp_path):
    """A hand-made recording: estimates at 10 Hz, truth at 20 Hz, fixes at 5 Hz, one garbage line."""
    lines = []
    for k in range(21):  # 0..2 s
        t_us = k * 100_000
        p = np.array([k * 1.0, 2.0, -10.0])
        lines.append(_line("uav7", "companion", "estimate", NavEstimate(
            t_us, p + np.array([0.5, 0.5, 0.0]), np.zeros(3), np.array([0.1, 0.2, 0.3]), np.full(9, 0.01),
            0.8, 1.5, "naive")))
    for k in range(41):
        t_us = k * 50_000
        lines.append(_line("uav7", "vehicle", "truth", TruthState(
            t_us, np.array([k * 0.5, 2.0, -10.0]), np.zeros(3), np.array([1.0, 0, 0, 0]),
            gnss_bias_ned_m=np.zeros(3), gnss_latency_s=0.1, clearance_m=4.0)))
    for k in range(11):
        fix = GnssFix(k * 200_000 - 100_000, 52.5 + k * 1e-6, 13.4, 35.0, 3, 12, 0.5, 0.8)
        lines.append(_line("uav7", "vehicle", "gnss", zc.GnssReport(k * 200_000, fix)))
    lines.append("{not json")
    rec = tmp_path / "rec.jsonl"
    rec.write_text("\n".join(lines) + "\n")
    assert main(["export", str(rec), "--out", str(tmp_path / "rec.csv"), "--format", "csv"]) == 0
    ts = _csv(tmp_path / "rec.csv")
    assert len(ts["t_s"]) == 21
    np.testing.assert_allclose(ts["est_error_m"], 0.5 * math.sqrt(2), rtol=1e-9)  # (0.5, 0.5, 0) off
    np.testing.assert_allclose(ts["beta"], 0.8)
    assert main(["export", str(rec), "--out", str(tmp_path / "rec.mcap")]) == 0
    _, msgs = _read(tmp_path / "rec.mcap")
    assert len(msgs["/gnss/fix"]) == 11
    assert msgs["/gnss/fix"][3][1]["position_covariance"][0] == pytest.approx(0.25)


def test_bad_inputs_are_one_line_errors(tmp_path, capsys):
    (tmp_path / "x.bin").write_bytes(b"\0")
    assert main(["export", str(tmp_path / "x.bin")]) == 2
    assert main(["export", str(tmp_path)]) == 2  # a directory without timeseries.csv
    assert main(["export", str(QUAD106), "--home", "1,2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(e.startswith("beliefnav: error: ") for e in err)
    assert "valid: a run directory, .tlog, .jsonl" in err[0]


def test_foxglove_layout_names_only_exported_topics_and_fields(run_dir, tmp_path):
    """docs/foxglove-layout.json and the export cannot drift apart: every topic and plotted field exists."""
    from gcs_tools.export.flight import SCALARS

    layout = json.loads((Path(__file__).parents[1] / "docs" / "foxglove-layout.json").read_text())
    out = tmp_path / "run.mcap"
    assert main(["export", str(run_dir), "--out", str(out)]) == 0
    channels, _ = _read(out)
    for panel, config in layout["configById"].items():
        for topic in config.get("topics", {}):
            assert topic.startswith(("/path/", "/pose/")), (panel, topic)
            assert topic.split("/")[2] in ("true", "estimated", "reference", "gnss", "autopilot")
        for path in config.get("paths", []):
            topic, field = path["value"].split(".", 1)
            assert topic in channels and field in SCALARS, (panel, path)


def test_replay_output_exports_estimate_belief_and_the_logs_fixes(tmp_path):
    """`beliefnav replay` of the real log, then export: the estimate, β and NIS of estimates.csv and
    every fix of the log (read again through summary.json's file) on the same boot-time clock."""
    run = tmp_path / "replay"
    assert main(["replay", str(QUAD106), "--out", str(run), "--no-progress"]) == 0
    assert main(["export", str(run), "--out", str(tmp_path / "r.mcap")]) == 0
    channels, msgs = _read(tmp_path / "r.mcap")
    est = _csv(run / "estimates.csv")
    assert len(msgs["/pose/estimated"]) == len(est["t_s"]) == len(msgs["/beliefnav/state"])
    assert len(msgs["/gnss/fix"]) == 3339
    for i in (0, len(est["t_s"]) // 2):
        _, st = msgs["/beliefnav/state"][i]
        assert st["beta"] == est["beta"][i] and st["b_est_e_m"] == est["b_e_m"][i]
    # the estimate follows the fixes: median horizontal gap well under a metre on this log
    gnss = {t: g["pose"]["position"] for t, g in msgs["/pose/gnss"]}
    gap = [math.hypot(p["pose"]["position"]["x"] - gnss[t]["x"], p["pose"]["position"]["y"] - gnss[t]["y"])
           for t, p in msgs["/pose/estimated"] if t in gnss]
    assert len(gap) > 0.9 * len(est["t_s"]) and float(np.median(gap)) < 1.0
