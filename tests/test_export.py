"""`beliefnav export`: MCAP read back with the `mcap` library (and CSV), compared with what the run
itself wrote: a fly run directory, a SITL run's tlog, a real tlog, a replay, a recording."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from companion.domain.rotation import enu_flu, rotation_matrix
from companion.domain.samples import GnssFix, NavEstimate, TruthState
from companion.mission import load_mission
from companion.telemetry import codec as zc
from gcs_tools.cli import main

QUAD106 = Path(__file__).parent / "data" / "quad106.tlog"
TEST_CITY = load_mission("test")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """`beliefnav fly` on the small test city under the mismatch scenario (seed 0 has one fix the
    gate rejects): the files a user exports."""
    out = tmp_path_factory.mktemp("fly")
    assert main(["fly", "--mission", "test", "--scenario", "mismatch", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def sitl_dir(tmp_path_factory) -> Path:
    """12 simulated seconds of `beliefnav sitl` (three processes; run.tlog beside timeseries.csv)."""
    out = tmp_path_factory.mktemp("sitl")
    rc = main(["sitl", "--mission", "test", "--out", str(out), "--no-progress", "--no-telemetry",
               "--max-duration-s", "12"])
    assert rc == 1 and (out / "run.tlog").is_file()  # (the time limit: not at the goal)
    return out


def _read(path: Path):
    """(topic -> (schema, schema encoding, message encoding), topic -> [(log_time_ns, message)], metadata)."""
    channels: dict[str, tuple[str, str, str]] = {}
    messages: dict[str, list[tuple[int, dict]]] = {}
    with path.open("rb") as f:
        reader = make_reader(f)
        for schema, channel, msg in reader.iter_messages(log_time_order=False):
            channels[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
            messages.setdefault(channel.topic, []).append((msg.log_time, json.loads(msg.data)))
    with path.open("rb") as f:
        meta = {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}
    return channels, messages, meta


def _csv(path: Path) -> dict[str, np.ndarray]:
    table = np.genfromtxt(path, delimiter=",", names=True)
    return {n: table[n] for n in table.dtype.names}


def _enu(p: dict) -> np.ndarray:
    """A pose position (ENU) as NED."""
    return np.array([p["y"], p["x"], -p["z"]])


def _q(o: dict) -> np.ndarray:
    return np.array([o["w"], o["x"], o["y"], o["z"]])


def test_orientation_is_body_flu_in_enu_for_any_attitude():
    """R_enu_flu = A R_ned_frd B (A swaps north/east and flips down, B flips y and z) for random
    attitudes; a vehicle heading north (NED yaw 0) faces ENU +y: yaw +90 degrees."""
    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    a, b = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1.0]]), np.diag([1.0, -1.0, -1.0])
    for qi, qe in zip(q, enu_flu(q), strict=True):
        np.testing.assert_allclose(rotation_matrix(qe), a @ rotation_matrix(qi) @ b, atol=1e-12)
        assert qe[0] >= 0
    np.testing.assert_allclose(enu_flu(np.array([1.0, 0, 0, 0]))[0], [math.sqrt(0.5), 0, 0, math.sqrt(0.5)])


def test_run_directory_to_mcap_matches_the_runs_own_files(run_dir, tmp_path):
    out = tmp_path / "run.mcap"
    assert main(["export", str(run_dir), "--out", str(out)]) == 0
    channels, msgs, meta = _read(out)
    assert channels["/pose/true"] == ("foxglove.PoseInFrame", "jsonschema", "json")
    assert channels["/path/estimated"] == ("foxglove.PosesInFrame", "jsonschema", "json")
    assert channels["/gnss/fix"][0] == channels["/map/true"][0] == "foxglove.LocationFix"
    assert channels["/map/buildings"][0] == "foxglove.SceneUpdate"
    assert channels["/beliefnav/state"][0] == "beliefnav.State"
    ts, summary = _csv(run_dir / "timeseries.csv"), json.loads((run_dir / "summary.json").read_text())
    n = len(ts["t_s"])
    state = msgs["/beliefnav/state"]
    assert len(state) == n == len(msgs["/pose/true"])
    # the metadata record: what was flown, by which version, where and when
    info = meta["beliefnav"]
    assert (info["mission"], info["method"], info["seed"], info["scenario"]) == (
        "test-city", "second-order", "0", "mismatch")
    assert info["beliefnav_version"] == summary["beliefnav_version"]
    assert info["exported_by"].startswith("beliefnav")
    assert info["home"] == "52.52000000,13.40500000,35.000" and "mission" in info["home_source"]
    # real time: the run's wall clock at its start + simulated time, every row once
    for i in (0, n // 2, n - 1):
        log_ns, st = state[i]
        assert log_ns == round((summary["start_unix_s"] + ts["t_s"][i]) * 1e9)
        for col in ("beta", "nis", "est_error_m", "track_error_m", "b_est_n_m", "latency_s"):
            v = ts[col][i]
            assert (st[col] is None) if math.isnan(v) else st[col] == v, col
    assert len({t for t, _ in msgs["/pose/estimated"]}) == len(msgs["/pose/estimated"])
    # poses in ENU with the true attitude (body FLU -> ENU)
    mid = n // 2
    _, pose = msgs["/pose/true"][mid]
    np.testing.assert_array_equal(_enu(pose["pose"]["position"]), [ts[f"p_true_{a}_m"][mid] for a in "ned"])
    q_ned = np.array([ts[f"q_true_{c}"][mid] for c in "wxyz"])
    np.testing.assert_allclose(_q(pose["pose"]["orientation"]), enu_flu(q_ned)[0], atol=1e-12)
    assert abs(_q(pose["pose"]["orientation"])[0] - 1) > 0.1  # not the identity (the vehicle faces north)
    # every fix of gnss.csv, at its arrival, where it was (round trip through WGS-84 < 1 mm)
    gnss = _csv(run_dir / "gnss.csv")
    fixes = msgs["/gnss/fix"]
    assert len(fixes) == len(gnss["t_s"]) == summary["gnss"]["fused"] + summary["gnss"]["rejected"]
    frame = TEST_CITY.frame
    for k in (0, len(fixes) // 2):
        log_ns, fix = fixes[k]
        assert log_ns == round((summary["start_unix_s"] + gnss["t_s"][k]) * 1e9)
        back = frame.to_ned_m(fix["latitude"], fix["longitude"], fix["altitude"])
        np.testing.assert_allclose(back, [gnss[f"p_{a}_m"][k] for a in "ned"], atol=1e-3)
        assert fix["position_covariance"][0] == pytest.approx(gnss["h_acc_m"][k] ** 2, rel=1e-5)
    red = [f for _, f in fixes if f["color"]["r"] > 0.8]
    assert len(red) == int(np.nansum(gnss["rejected"])) == 1  # the rejected fix, coloured
    # the map: true track in WGS-84; the buildings as boxes of the mission's size
    _, m = msgs["/map/true"][mid]
    np.testing.assert_allclose(frame.to_ned_m(m["latitude"], m["longitude"], m["altitude"]),
                               [ts[f"p_true_{a}_m"][mid] for a in "ned"], atol=1e-3)
    (_, scene), = msgs["/map/buildings"]
    cubes = scene["entities"][0]["cubes"]
    assert len(cubes) == len(TEST_CITY.world.config.buildings)
    b0 = TEST_CITY.world.config.buildings[0]
    assert cubes[0]["size"] == {"x": b0.east_max_m - b0.east_min_m, "y": b0.north_max_m - b0.north_min_m,
                                "z": b0.height_m}


def test_run_directory_to_csv_equals_timeseries(run_dir, tmp_path):
    out = tmp_path / "run.csv"
    assert main(["export", str(run_dir), "--format", "csv", "--out", str(out)]) == 0
    a, b = _csv(run_dir / "timeseries.csv"), _csv(out)
    assert set(a) < set(b)
    for col in a:
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)
    start = json.loads((run_dir / "summary.json").read_text())["start_unix_s"]
    np.testing.assert_allclose(b["t_unix_s"], start + a["t_s"], atol=2e-6)
    assert np.isfinite(b["p_gnss_n_m"][20:]).all()  # the last fix received, held


def test_sitl_tlog_export_matches_the_runs_timeseries(sitl_dir, tmp_path, capsys):
    """The tlog alone (no --home): the frame from its GPS_GLOBAL_ORIGIN, each estimate once on its
    own boot time, equal to timeseries.csv at the row times (ODOMETRY is float32: 0.1 mm), truth
    from SIM_STATE within 1 cm, the wall clock of its SYSTEM_TIME."""
    out = tmp_path / "tlog.mcap"
    assert main(["export", str(sitl_dir / "run.tlog"), "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["home"]["source"] == "the log's GPS_GLOBAL_ORIGIN" and not report["warnings"]
    channels, msgs, meta = _read(out)
    epoch = float(meta["beliefnav"]["epoch_unix_s"])
    summary = json.loads((sitl_dir / "summary.json").read_text())
    # the vehicle's clock starts after the command did and before the run ended (a loaded machine
    # takes seconds to start the processes)
    assert summary["start_unix_s"] <= epoch <= (sitl_dir / "summary.json").stat().st_mtime
    ts = _csv(sitl_dir / "timeseries.csv")
    for topic, prefix, tol in (("/pose/estimated", "p_est", 2e-4), ("/pose/true", "p_true", 0.01)):
        times = [t for t, _ in msgs[topic]]
        assert len(set(times)) == len(times), topic  # no duplicates
        by_t = {round(t / 1e9 - epoch, 3): m["pose"]["position"] for t, m in msgs[topic]}
        err = [np.abs(_enu(by_t[round(t, 3)]) - [ts[f"{prefix}_{a}_m"][i] for a in "ned"]).max()
               for i, t in enumerate(ts["t_s"]) if i > 5 and round(t, 3) in by_t]
        assert len(err) > 0.9 * len(ts["t_s"]) and max(err) < tol, (topic, max(err))
    gnss = _csv(sitl_dir / "gnss.csv")
    assert len(msgs["/gnss/fix"]) == len(gnss["t_s"]) == summary["gnss"]["sent"]
    assert len(msgs["/map/buildings"]) == 1  # the mission of the run directory it sits in


def test_home_far_from_the_log_is_refused_and_a_different_one_warned_about(sitl_dir, tmp_path, capsys):
    tlog = str(sitl_dir / "run.tlog")
    assert main(["export", tlog, "--out", str(tmp_path / "x.mcap"), "--home", "10,10,0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("beliefnav: error: --home 10,10,0: ")
    assert "km from the flight" in err[0]
    assert not (tmp_path / "x.mcap").exists()
    # 0.0001 degrees north of the mission's home: used, with one warning naming the distance
    assert main(["export", tlog, "--out", str(tmp_path / "y.mcap"), "--home", "52.5201,13.405,35"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("beliefnav: warning: --home is 11.1 m from the flight's own origin")
    _, shifted, _ = _read(tmp_path / "y.mcap")
    assert main(["export", tlog, "--out", str(tmp_path / "z.mcap")]) == 0
    _, plain, _ = _read(tmp_path / "z.mcap")
    d = _enu(plain["/pose/estimated"][50][1]["pose"]["position"]) - _enu(
        shifted["/pose/estimated"][50][1]["pose"]["position"])
    assert d[0] == pytest.approx(11.13, abs=0.02) and abs(d[1]) < 1e-3  # the same point, about --home


def test_real_tlog_exports_every_fix_on_its_wall_clock(tmp_path, capsys):
    out = tmp_path / "q.mcap"
    assert main(["export", str(QUAD106), "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["messages"]["/gnss/fix"] == report["fixes"] == 3339  # every GPS_RAW_INT is a 3-D fix
    assert report["home"]["source"] == "the first 3-D fix"  # the log has no origin, no mission
    channels, msgs, _ = _read(out)
    from companion.mavlink import codec
    from companion.mavlink.tlog import read_tlog

    system_time = next(m for _, m in read_tlog(QUAD106, ["SYSTEM_TIME"]) if m.time_unix_usec > 0)
    epoch = system_time.time_unix_usec * 1e-6 - system_time.time_boot_ms * 1e-3
    first = codec.decode_gnss(next(m for _, m in read_tlog(QUAD106, ["GPS_RAW_INT"])))
    _, fix0 = msgs["/gnss/fix"][0]
    assert (fix0["latitude"], fix0["longitude"]) == (first.lat_deg, first.lon_deg)
    stamp = fix0["timestamp"]["sec"] + fix0["timestamp"]["nsec"] * 1e-9
    assert stamp == pytest.approx(epoch + first.t_validity_us * 1e-6, abs=1e-6)  # validity, on UTC
    _, pose0 = msgs["/pose/gnss"][0]  # home = the first fix: the first GNSS pose is the origin
    assert all(abs(v) < 1e-6 for v in pose0["pose"]["position"].values())
    assert "/pose/estimated" not in channels  # the log has no onboard estimate: nothing made up


def _line(vehicle: str, process: str, topic: str, obj, sent_ns: int = 0) -> str:
    payload = json.loads(zc.encode(topic, obj, sent_ns))
    return json.dumps({"key": zc.key_for(vehicle, process, topic), "recv_unix_ns": 0, "payload": payload})


def test_recording_exports_estimates_truth_and_fixes(tmp_path, capsys):
    """A hand-made recording: estimates at 10 Hz (published 1.7e9 s after boot time 0), truth at 20 Hz,
    fixes at 5 Hz, one garbage line."""
    lines = []
    for k in range(21):  # 0..2 s
        t_us = k * 100_000
        p = np.array([k * 1.0, 2.0, -10.0])
        lines.append(_line("uav7", "companion", "estimate", NavEstimate(
            t_us, p + np.array([0.5, 0.5, 0.0]), np.zeros(3), np.array([0.1, 0.2, 0.3]), np.full(9, 0.01),
            0.8, 1.5, "naive"), 1_700_000_000 * 10**9 + t_us * 1000))
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
    assert main(["export", str(rec), "--out", str(tmp_path / "rec.csv"), "--format", "csv",
                 "--vehicle-id", "uav7"]) == 0
    ts = _csv(tmp_path / "rec.csv")
    assert len(ts["t_s"]) == 21
    np.testing.assert_allclose(ts["est_error_m"], 0.5 * math.sqrt(2), rtol=1e-9)  # (0.5, 0.5, 0) off
    np.testing.assert_allclose(ts["beta"], 0.8)
    np.testing.assert_allclose(ts["t_unix_s"], 1.7e9 + ts["t_s"], atol=1e-6)
    # the old spelling still works, with a note
    assert main(["export", str(rec), "--out", str(tmp_path / "rec.mcap"), "--vehicle", "uav7"]) == 0
    assert "--vehicle is now --vehicle-id" in capsys.readouterr().err
    _, msgs, _ = _read(tmp_path / "rec.mcap")
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
    """docs/foxglove-layout.json and the export cannot drift apart: every topic and plotted field
    exists in a run's export, and the layout shows the buildings, the fixes and both map tracks."""
    from gcs_tools.export.flight import SCALARS

    layout = json.loads((Path(__file__).parents[1] / "docs" / "foxglove-layout.json").read_text())
    out = tmp_path / "run.mcap"
    assert main(["export", str(run_dir), "--out", str(out)]) == 0
    channels, _, _ = _read(out)
    named = set()
    for panel, config in layout["configById"].items():
        for topic in config.get("topics", {}):
            assert topic in channels, (panel, topic)
            named.add(topic)
        for path in config.get("paths", []):
            topic, field = path["value"].split(".", 1)
            assert topic in channels and field in SCALARS, (panel, path)
        named |= set(config.get("topicColors", {}))
    assert {"/map/buildings", "/gnss/fix", "/map/true", "/map/estimated"} <= named


def test_replay_output_exports_estimate_belief_attitude_and_the_logs_fixes(tmp_path, quad106_replayed):
    """`beliefnav replay` of the real log, then export: the estimate, β and NIS of estimates.csv, the
    attitude the estimator was given, every fix of the log (read again through summary.json's
    file), on the log's clock mapped to UTC by its SYSTEM_TIME."""
    run, _ = quad106_replayed  # `beliefnav replay QUAD106 --out RUN --no-progress`, exit 0
    assert main(["export", str(run), "--out", str(tmp_path / "r.mcap")]) == 0
    channels, msgs, meta = _read(tmp_path / "r.mcap")
    est = _csv(run / "estimates.csv")
    assert len(msgs["/pose/estimated"]) == len(est["t_s"]) == len(msgs["/beliefnav/state"])
    assert len(msgs["/gnss/fix"]) == 3339
    epoch = float(meta["beliefnav"]["epoch_unix_s"])
    for i in (0, len(est["t_s"]) // 2):
        log_ns, st = msgs["/beliefnav/state"][i]
        assert st["beta"] == est["beta"][i] and st["b_est_e_m"] == est["b_e_m"][i]
        assert log_ns == round((epoch + est["t_s"][i]) * 1e9)
    orientations = np.array([_q(p["pose"]["orientation"]) for _, p in msgs["/pose/estimated"]])
    assert np.ptp(orientations, axis=0).max() > 0.1  # the log's attitude, not a constant
    # the estimate follows the fixes: median horizontal gap well under a metre on this log
    fixes = np.array([_enu(g["pose"]["position"]) for _, g in msgs["/pose/gnss"]])
    t_fix = np.array([t for t, _ in msgs["/pose/gnss"]])
    gap = []
    for t, p in msgs["/pose/estimated"]:
        k = np.searchsorted(t_fix, t) - 1
        if k >= 0 and t - t_fix[k] < 0.25e9:  # the last fix (5 Hz), as the table holds it
            gap.append(np.hypot(*(_enu(p["pose"]["position"]) - fixes[k])[:2]))
    assert len(gap) > 0.9 * len(est["t_s"]) and float(np.median(gap)) < 1.0


def test_replay_with_synthetic_fixes_does_not_export_the_logs_own(tmp_path, capsys):
    """A replay on --gnss-errors: the estimator never saw the log's fixes, so they are not exported as
    its fixes (they were, all 3339 of the clean receiver); the attitude still is, with a warning."""
    short = tmp_path / "short.tlog"
    short.write_bytes(QUAD106.read_bytes()[:400_000])
    run = tmp_path / "replay"
    assert main(["replay", str(short), "--gnss-errors", "model", "--out", str(run), "--no-figures"]) == 0
    capsys.readouterr()
    assert main(["export", str(run), "--out", str(tmp_path / "r.mcap")]) == 0
    assert "the replay's GNSS was not the log's own" in capsys.readouterr().err
    _, msgs, _ = _read(tmp_path / "r.mcap")
    assert not msgs.get("/gnss/fix") and len(msgs["/pose/estimated"]) > 100


def test_an_autopilots_repeated_gps_raw_int_is_one_fix(tmp_path, capsys):
    """ArduPilot streams GPS_RAW_INT faster than its receiver updates (measured beside ArduCopter
    SITL: each 5 Hz fix four times, same ``time_usec``): each fix is exported once, at its first
    arrival, in the log's GPS_GLOBAL_ORIGIN frame."""
    from pymavlink.dialects.v20 import common as mav

    from companion.mavlink.tlog import TlogWriter

    tlog = tmp_path / "ap.tlog"
    lat0, lon0 = -353632610, 1491652300
    unix0_us = 1_795_000_000_000_000
    with TlogWriter(tlog) as w:
        w.write(unix0_us, mav.MAVLink_system_time_message(unix0_us, 0))
        w.write(unix0_us, mav.MAVLink_gps_global_origin_message(lat0, lon0, 584_000))
        for k in range(10):  # fixes at 5 Hz, each sent 4 times at 20 Hz
            for r in range(4):
                t_us = 200_000 * k + 50_000 * r
                w.write(unix0_us + t_us, mav.MAVLink_gps_raw_int_message(
                    200_000 * k, 3, lat0 + 10 * k, lon0, 584_000, 121, 200, 0, 0, 10))
    out = tmp_path / "ap.mcap"
    assert main(["export", str(tlog), "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["fixes"] == report["messages"]["/gnss/fix"] == 10
    _, msgs, _ = _read(out)
    lats = [m["latitude"] for _, m in msgs["/gnss/fix"]]
    assert lats == pytest.approx([(lat0 + 10 * k) * 1e-7 for k in range(10)], abs=1e-9)
    north = [m["pose"]["position"]["y"] for _, m in msgs["/pose/gnss"]]  # ENU: y is north
    # 1e-6 deg of latitude is 0.111 m (within 1 % of a spherical Earth's 0.1113 m)
    assert north == pytest.approx([k * 0.1113 for k in range(10)], rel=0.01, abs=1e-6)


def test_a_companion_recording_is_exported_about_its_routes_home(tmp_path, capsys):
    """``beliefnav companion`` beside an autopilot publishes no truth and a route without waypoints
    whose ``home_lla`` is its frame: the fixes land where the estimates are (here: on them)."""
    from companion.domain.geodesy import LocalNedFrame
    from companion.domain.samples import NavEstimate

    home = LocalNedFrame(-35.3632610, 149.1652300, 584.0)
    route = zc.RouteInfo(0, "", 0, np.zeros((0, 3)), 0.0, home_lla=np.array([-35.363261, 149.16523, 584.0]))
    lines = [_line("ap1", "companion", "route", route)]
    for k in range(21):
        t_us = k * 100_000
        p = np.array([3.0 + k * 0.5, -4.0, -2.0])
        lines.append(_line("ap1", "companion", "estimate", NavEstimate(
            t_us, p, np.zeros(3), np.zeros(3), np.full(9, 0.01), 0.9, 1.0, "second-order"),
            1_795_000_000 * 10**9 + t_us * 1000))
        if k % 2 == 0:
            lat, lon, alt = home.to_geodetic(p)
            fix = GnssFix(t_us, lat, lon, alt, 3, 10, 0.5, 0.8)
            lines.append(_line("ap1", "companion", "gnss", zc.GnssReport(t_us, fix)))
    rec = tmp_path / "ap.jsonl"
    rec.write_text("\n".join(lines) + "\n")
    out = tmp_path / "ap.mcap"
    assert main(["export", str(rec), "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["home"]["source"] == "the route's home" and not report.get("warnings"), report
    _, msgs, meta = _read(out)
    est = {t: m["pose"]["position"] for t, m in msgs["/pose/estimated"]}
    gnss = msgs["/pose/gnss"]
    assert len(gnss) == 11
    for t, m in gnss:  # the fix's pose is the estimate's, in the same enu frame, to a millimetre
        e, g = est[t], m["pose"]["position"]
        assert (g["x"], g["y"], g["z"]) == pytest.approx((e["x"], e["y"], e["z"]), abs=1e-3)
    assert "mission" not in meta["beliefnav"]

