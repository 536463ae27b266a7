"""End-to-end SITL: three real processes over MAVLink/UDP on free loopback ports."""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from sitl_helpers import Trio, children_of, require_pieces, route_duration_s, run_cli

pytestmark = [pytest.mark.slow, pytest.mark.timeout(60)]
MISSION = "test"


@pytest.fixture(autouse=True)
def _pieces():
    require_pieces()


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


SEED = 5  # the shared lockstep flight: test mission, profile 0


@pytest.fixture(scope="module")
def lockstep_flight(tmp_path_factory) -> Path:
    """One lockstep flight through the CLI; the tests below only read what it left."""
    require_pieces()
    out = tmp_path_factory.mktemp("lockstep")
    done = run_cli("--mission", MISSION, "--profile", "0", "--seed", str(SEED), "--out", str(out),
                   figures=True)
    assert done.returncode == 0, done.stderr
    assert all((out / name).stat().st_size > 10_000 for name in ("map.png", "belief.png"))  # the one sitl
    return out  # flight here that draws them: the others pass --no-figures


def _series(out: Path) -> dict[str, np.ndarray]:
    with np.load(out / "vehicle_series.npz") as npz:
        return {k: npz[k] for k in npz.files}


@pytest.fixture(scope="module")
def lockstep_replay(lockstep_flight):
    """The shared flight's tlog replayed (second-order, the test mission's filter, every IMU row)."""
    from companion.mission import load_mission
    from companion.wiring import mission_estimator_config
    from gcs_tools.replay.core import replay

    mission = load_mission(MISSION)
    assert mission.section("estimator"), "the test mission should carry a non-default estimator section"
    return replay(lockstep_flight / "run.tlog", "second-order", home=mission.frame,
                  config=mission_estimator_config(mission), rate_hz=0)


def _replayed(result, first_column: str) -> dict[int, np.ndarray]:
    """{t_us: the replay's three columns from ``first_column``} (e.g. p_n_m: p_n, p_e, p_d)."""
    from gcs_tools.replay.core import CSV_COLUMNS

    col = CSV_COLUMNS.index(first_column) - 1
    return {int(t): row[col:col + 3] for t, row in zip(result.t_us, result.table, strict=True)}


def test_lockstep_flight_arrives_and_its_tlog_is_standard_and_replays(lockstep_flight, lockstep_replay):
    a = _summary(lockstep_flight)
    assert a["reached_goal"] and a["estimation_error_m"]["median"] < 5.0
    assert a["sitl"]["lockstep"]["gave_up"] == 0

    tlog = lockstep_flight / "run.tlog"
    dump = subprocess.run([sys.executable, str(Path(sys.executable).parent / "mavlogdump.py"),
                           "--types", "GPS_RAW_INT,ODOMETRY,SYSTEM_TIME", str(tlog)],
                          capture_output=True, text=True, timeout=50)
    assert dump.returncode == 0
    assert "GPS_RAW_INT" in dump.stdout and "ODOMETRY" in dump.stdout and "SYSTEM_TIME" in dump.stdout

    from companion.mavlink.tlog import read_tlog

    live: dict[int, tuple[float, float, float]] = {}
    for _, m in read_tlog(tlog, ("ODOMETRY",)):
        if m.time_usec % 20_000 == 0:  # 50 Hz ODOMETRY, sent right after its IMU sample
            live.setdefault(int(m.time_usec), (m.x, m.y, m.z))
    result = lockstep_replay
    replayed = _replayed(result, "p_n_m")
    common = sorted(set(live) & set(replayed))
    assert len(common) > 0.9 * len(live) > 500
    diff = np.array([np.asarray(live[t]) - replayed[t] for t in common])
    scale = np.array([np.abs(replayed[t]) for t in common]) + 1.0
    assert np.max(np.abs(diff) / scale) < 2e-7  # float32 of the ODOMETRY fields
    assert "SIM_STATE" in json.dumps(result.summary["errors"]) or result.summary["errors"]


def test_lockstep_tlog_has_each_frame_once_monotonic_stamps_and_a_real_date(lockstep_flight):
    from companion.mavlink.codec import mavlink
    from companion.mavlink.tlog import read_tlog

    frames = list(read_tlog(lockstep_flight / "run.tlog", ("HEARTBEAT", "SYSTEM_TIME", "ODOMETRY")))
    stamps = [stamp for stamp, _ in read_tlog(lockstep_flight / "run.tlog")]
    assert all(b >= a for a, b in zip(stamps, stamps[1:], strict=False))  # never backwards
    assert time.time() - 3600 < stamps[0] / 1e6 <= time.time()  # anchored to the wall clock at start
    clocks = [m for _, m in frames if m.get_type() == "SYSTEM_TIME"]
    epochs = {m.time_unix_usec - m.time_boot_ms * 1000 for m in clocks}
    assert len(epochs) == 1 and abs(epochs.pop() - stamps[0]) < 1_000_000  # stamp = epoch + simulated time
    boots = [m.time_boot_ms for m in clocks]
    assert len(boots) == len(set(boots)) > 3  # once each (it is sent to both companions)
    beats = [m for _, m in frames if m.get_type() == "HEARTBEAT"]
    vehicle_beats = [b for b in beats if b.type == mavlink.MAV_TYPE_QUADROTOR]
    assert len(vehicle_beats) == len(clocks)
    assert all(b.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED for b in vehicle_beats)
    odometry = [m.time_usec for _, m in frames if m.get_type() == "ODOMETRY"]
    assert len(odometry) == len(set(odometry)) > 100  # one ODOMETRY per estimate time


def test_lockstep_is_reproducible_when_a_companion_stalls_and_bad_datagrams_are_rejected(lockstep_flight,
                                                                                      tmp_path):
    """The same flight again (signed with a key file), with bad datagrams and wrong-key frames sent at
    every port at 2 s of simulated time, and the estimator stopped (SIGSTOP) for 1.5 s of wall time
    from 5 s on, as a loaded machine may deschedule it: every bad datagram is counted and rejected, the
    vehicle waits for the estimator, and every recorded series is bit-identical to the undisturbed
    flight's (nothing that was rejected changed a bit). One flight for the two checks."""
    from companion.mission import load_mission
    from simvehicle.harness.sitl.launcher import SitlOptions
    from simvehicle.harness.sitl.supervisor import free_udp_ports

    key_file = tmp_path / "key"
    key_file.write_text("beliefnav-test-key")
    out = tmp_path / "stalled"
    est_port = free_udp_ports(1)[0]
    trio = Trio(out, SitlOptions(MISSION, 0, "second-order", SEED, out, signing_key_file=key_file),
                estimator_bind_port=est_port)
    try:
        trio.wait_sim_time(2.0, 30)
        _send_bad_datagrams(trio, est_port, key_file, load_mission(MISSION).frame)
        trio.wait_sim_time(5.0, 30)
        estimator = trio.sup.children["estimator"]
        os.kill(estimator.pid, signal.SIGSTOP)
        try:
            time.sleep(1.5)
        finally:
            os.kill(estimator.pid, signal.SIGCONT)
        vehicle = trio.wait_vehicle(50)
    finally:
        trio.stop()
    assert vehicle["lockstep"]["gave_up"] == 0 and vehicle["lockstep"]["retries"] >= 50  # it waited
    reference = json.loads((lockstep_flight / "vehicle.json").read_text())
    assert (vehicle["outcome"], vehicle["t_s"]) == (reference["outcome"], reference["t_s"])
    a, b = _series(lockstep_flight), _series(out)
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    # the bad datagrams: counted and rejected where they arrived
    est = json.loads((out / "estimator.json").read_text())
    assert vehicle["outcome"] == "reached_goal"
    assert est["link"]["bad_signature"] >= 20  # the wrong-key GPS
    links = vehicle["links"]
    assert links["bridge"]["bad_signature"] >= 20  # the wrong-key setpoints
    e = links["estimator"]
    assert e["garbage"] >= 20 and e["bad_crc"] >= 20 and e["unknown_message"] >= 20
    assert e["wrong_system_id"] >= 20  # correctly signed, but not our system


def _send_bad_datagrams(trio: Trio, est_port: int, key_file: Path, home) -> None:
    """20 rounds of: a wrong-key GPS fix to the estimator, a wrong-key setpoint to the vehicle's bridge
    port, garbage, a bad CRC, an unknown message id and a right-key HEARTBEAT of system 42 to the
    vehicle's estimator port."""
    from companion.domain.samples import GnssFix, Setpoint
    from companion.mavlink import codec as codec
    from companion.mavlink.udp_link import read_signing_key

    lat, lon, alt = home.to_geodetic(np.array([500.0, 500.0, -30.0]))
    bad_fix = codec.encode_gnss(GnssFix(1_000_000, lat, lon, alt, 3, 12))
    far = np.array([500.0, 500.0, -30.0])
    bad_sp = codec.encode_setpoint(Setpoint(1_000, far, np.zeros(3), np.zeros(3)))
    wrong, right = b"x" * 32, read_signing_key(key_file)
    ok = _frame(codec.encode_heartbeat("companion"), 1)
    bad_crc = bytearray(ok)
    bad_crc[-1] ^= 0xFF
    unknown = bytearray(ok)
    unknown[7:10] = bytes((0x21, 0x43, 0x0E))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for _ in range(20):
            s.sendto(_frame(bad_fix, 1, wrong), ("127.0.0.1", est_port))
            s.sendto(_frame(bad_sp, 1, wrong), ("127.0.0.1", trio.ports[1]))
            s.sendto(b"\x00garbage", ("127.0.0.1", trio.ports[0]))
            s.sendto(bytes(bad_crc), ("127.0.0.1", trio.ports[0]))
            s.sendto(bytes(unknown), ("127.0.0.1", trio.ports[0]))
            s.sendto(_frame(codec.encode_heartbeat("companion"), 42, right), ("127.0.0.1", trio.ports[0]))
            time.sleep(0.01)


def test_lockstep_sitl_agrees_with_in_process_fly(lockstep_flight):
    fly_mod = pytest.importorskip("simvehicle.harness.fly")
    from companion.mission import load_mission

    sitl = _summary(lockstep_flight)
    fly = fly_mod.fly(load_mission(MISSION), 0, "second-order", SEED).summary
    for key in ("estimation_error_m", "tracking_error_m"):
        a, b = sitl[key]["median"], fly[key]["median"]
        assert math.isclose(a, b, rel_tol=0.05), (key, a, b)


def test_estimated_bias_reaches_the_vehicle_series_and_exports(lockstep_flight, lockstep_replay, tmp_path):
    """The estimator's bias travels as DEBUG_VECT GNSS_BIAS (5 Hz): every finite row of the vehicle's
    b_est_ned_m is one of the vectors sent, and each vector sent is the estimator's bias at its stamp
    (replaying the tlog reproduces it to float32). `beliefnav export` of the tlog carries it on."""
    from companion.mavlink import codec
    from companion.mavlink.tlog import read_tlog

    tlog = lockstep_flight / "run.tlog"
    vectors: dict[int, np.ndarray] = {}
    for _, m in read_tlog(tlog, ["DEBUG_VECT"]):
        t_us, b = codec.decode_bias(m)
        vectors.setdefault(t_us, b)
    sent = {tuple(b) for b in vectors.values()}
    s = _series(lockstep_flight)
    b_est = s["b_est_ned_m"]
    ok = np.isfinite(b_est).all(axis=1)
    assert ok.mean() > 0.95 and len(sent) > 0.15 * len(b_est) / 4  # 5 Hz of 20 Hz rows, mostly distinct
    assert all(tuple(row) in sent for row in b_est[ok])
    replayed = _replayed(lockstep_replay, "b_n_m")
    common = sorted(set(vectors) & set(replayed))
    assert len(common) > 0.9 * len(vectors) > 50
    diff = np.array([vectors[t] - replayed[t] for t in common])
    scale = np.array([np.abs(replayed[t]) for t in common]) + 1.0
    assert np.max(np.abs(diff) / scale) < 2e-7  # float32 of the DEBUG_VECT fields

    from mcap.reader import make_reader

    done = subprocess.run([sys.executable, "-m", "gcs_tools", "export", str(lockstep_flight / "run.tlog"),
                           "--out", str(tmp_path / "run.mcap"), "--home", "52.52,13.405,35"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    with (tmp_path / "run.mcap").open("rb") as f:
        states = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=["/beliefnav/state"])]
    exported = np.array([[st[f"b_est_{a}_m"] for a in "ned"] for st in states if st["b_est_n_m"] is not None])
    assert len(exported) > 0.9 * len(states)
    sent_arr = np.array(sorted(sent))  # linear interpolation between sent vectors stays inside their range
    assert (exported >= sent_arr.min(axis=0) - 1e-9).all() and (exported <= sent_arr.max(axis=0) + 1e-9).all()
    assert np.std(exported[:, 0]) > 0.5 * np.std(sent_arr[:, 0])


def test_ten_percent_loss_both_ways_still_reaches_goal(tmp_path):
    done = run_cli("--mission", MISSION, "--profile", "2", "--seed", "2", "--out", str(tmp_path),
                   "--drop-probability", "0.1")
    assert done.returncode == 0, done.stderr
    s = _summary(tmp_path)
    assert s["reached_goal"], s
    assert s["sitl"]["links"]["vehicle"]["estimator"]["dropped_tx"] > 100
    assert s["sitl"]["links"]["estimator"]["dropped_tx"] > 10
    assert s["sitl"]["lockstep"]["retries"] > 10


def _frame(msg, system_id: int, key: bytes | None = None) -> bytes:
    """One packed frame from ``system_id``, signed with ``key`` when given."""
    from companion.mavlink import codec as codec

    mav = codec.new_link(system_id, 1)
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        mav.signing.timestamp = int((time.time() - 1_420_070_400) * 100_000)
    return codec.pack(mav, msg)


def test_companion_killed_and_restarted_vehicle_holds_and_flight_continues(tmp_path):
    """While the estimator is dead the autopilot holds zero velocity in its own dead-reckoned
    frame, started from the last estimate: so the truth drifts at exactly minus that estimate's
    velocity error (the estimator's velocity error is 0.4 m/s median, 0.8 m/s p90 on this
    mission; with a perfect estimate the drift is < 0.3 m, see test_vehicle_autopilot).
    Stated bounds: from 2 s after the hold began the true velocity is within 0.3 m/s of minus the
    estimate's velocity error at the loss, and braking from cruise takes less than 8 m."""
    from companion.mavlink.tlog import read_tlog
    from simvehicle.harness.sitl.launcher import SitlOptions

    out = tmp_path / "run"
    opts = SitlOptions(MISSION, 0, "second-order", 6, out, route_duration_s(MISSION, 0) + 30)
    trio = Trio(out, opts)
    try:
        trio.wait_sim_time(10.0, 30)
        estimator = trio.sup.children["estimator"]
        estimator.kill()
        estimator.wait()
        t_kill = trio.poll_progress()
        time.sleep(1.0)  # the outage lasts > 3 s of simulated time even on an idle machine
        trio.start("estimator", tag="2")
        vehicle = trio.wait_vehicle(50)
    finally:
        trio.stop()
    assert vehicle["outcome"] == "reached_goal"
    assert vehicle["links"]["estimator"]["peer_refused"] >= 1  # known gone at once (closed port)
    assert vehicle["lockstep"]["gave_up"] >= 1
    series = _series(out)
    t, err = series["t_s"], series["est_error_m"]
    p_true, p_est = series["p_true_ned_m"], series["p_est_ned_m"]
    assert np.all(np.isfinite(p_true)) and t[-1] > t_kill + 5
    # The outage: periods that brought no newer ODOMETRY (the last estimate repeats exactly).
    frozen = np.r_[False, np.all(p_est[1:] == p_est[:-1], axis=1)]
    edges = np.flatnonzero(np.diff(frozen.astype(int)))
    first, last = edges[0] + 1, edges[1]  # the first run of frozen rows
    hold_t = t[first] + 0.5  # the estimate turns stale
    assert t[last] - hold_t > 3.0
    v_true = np.gradient(p_true, t, axis=0)
    held = [m for _, m in read_tlog(out / "run.tlog", ("ODOMETRY",))
            if np.array_equal((m.x, m.y, m.z), p_est[first])][-1]  # the estimate the autopilot kept
    v_err = np.array([held.vx, held.vy, held.vz]) - v_true[first - 1]
    settled = (t >= hold_t + 2.0) & (t <= t[last])
    assert np.all(np.linalg.norm(v_true[settled] + v_err, axis=1) < 0.3), (v_err, v_true[settled])
    hold = (t >= hold_t) & (t <= t[last])
    assert np.max(np.linalg.norm(p_true[hold] - p_true[np.flatnonzero(hold)[0]], axis=1)) < 8.0
    est2 = json.loads((out / "estimator2.json").read_text())
    assert est2["navigator"]["gnss_fused"] > 50  # re-initialised from GNSS
    assert np.nanmedian(err[t > t_kill + 10]) < 5.0


@pytest.mark.parametrize("how", ["interrupt", "crash", "timeout"])
def test_launcher_never_leaves_processes_behind(tmp_path, how):
    out = tmp_path / "run"
    args = [sys.executable, "-m", "gcs_tools", "sitl", "--no-progress", "--no-figures", "--mission", MISSION,
            "--realtime", "--out", str(out)]
    if how == "timeout":
        args += ["--wall-timeout-s", "9"]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while len(children_of(out)) < 3 or not (out / "vehicle.json").exists():  # flying (written each 1 s)
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.1)
        time.sleep(1.0)  # a second of real-time flight on record (duration_s, run.tlog below)
        if how == "interrupt":
            proc.send_signal(signal.SIGINT)
        elif how == "crash":
            victim = next(p for p in children_of(out)
                          if b"companion\0estimator" in Path(f"/proc/{p}/cmdline").read_bytes())
            os.kill(victim, signal.SIGKILL)
        _, stderr = proc.communicate(timeout=25)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert children_of(out) == []
    assert proc.returncode != 0
    summary = _summary(out)
    expected = {"interrupt": "interrupted", "crash": "crash:estimator", "timeout": "timeout"}[how]
    assert summary["sitl"]["ended_by"] == expected
    assert summary["duration_s"] > 0.2 and (out / "run.tlog").stat().st_size > 1_000
    if how == "crash":
        assert "beliefnav: error: estimator process killed by SIGKILL" in stderr


def _mavproxy_seen(tmp_path: Path) -> set[str]:
    """GPS_RAW_INT and the NAMED_VALUE_FLOAT names in MAVProxy's log so far (it may be mid-write)."""
    from companion.mavlink.tlog import read_tlog

    seen: set[str] = set()
    for log in tmp_path.rglob("proxy.tlog"):
        with contextlib.suppress(OSError, ValueError):
            for _, m in read_tlog(log, ("GPS_RAW_INT", "NAMED_VALUE_FLOAT")):
                name = m.get_type() if m.get_type() != "NAMED_VALUE_FLOAT" else m.name
                seen.add(name.decode() if isinstance(name, bytes) else name)
    return seen


def test_mavproxy_sees_gps_and_belief_on_the_ground_port(tmp_path):
    """A real MAVProxy on the ground port (udpout: it speaks first) logs our GPS and the belief; the
    flight (real time) is interrupted once it has, or after 20 s of wall time."""
    mavproxy = Path(sys.executable).parent / "mavproxy.py"
    if not mavproxy.exists():
        pytest.skip("MAVProxy not installed (pip install --no-deps mavproxy)")
    from simvehicle.harness.sitl.supervisor import free_udp_ports

    ports = free_udp_ports(3)
    out = tmp_path / "run"
    proxy = subprocess.Popen(
        [sys.executable, str(mavproxy), f"--master=udpout:127.0.0.1:{ports[2]}", "--daemon",
         "--non-interactive", f"--state-basedir={tmp_path}", "--logfile=proxy.tlog",
         "--default-modules=", "--nowait"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path,
        start_new_session=True,
    )
    try:
        sitl = subprocess.Popen(
            [sys.executable, "-m", "gcs_tools", "sitl", "--no-progress", "--no-figures", "--mission", MISSION,
             "--realtime", "--max-duration-s", "20", "--out", str(out), "--ports", ",".join(map(str, ports)),
             "--no-signing"],  # MAVProxy has no key here
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 50
            while sitl.poll() is None and time.monotonic() < deadline:
                if {"GPS_RAW_INT", "GNSS_BETA"} <= _mavproxy_seen(tmp_path):
                    sitl.send_signal(signal.SIGINT)
                    break
                time.sleep(0.25)
            _, stderr = sitl.communicate(timeout=30)
        finally:
            if sitl.poll() is None:
                sitl.kill()
    finally:
        os.killpg(proxy.pid, signal.SIGTERM)
        try:
            proxy.wait(timeout=5)
        except subprocess.TimeoutExpired:
            os.killpg(proxy.pid, signal.SIGKILL)
    assert list(tmp_path.rglob("proxy.tlog")), "MAVProxy wrote no log"
    seen = _mavproxy_seen(tmp_path)
    assert "GPS_RAW_INT" in seen and "GNSS_BETA" in seen, seen
    s = _summary(out)
    assert s["sitl"]["ended_by"] in ("interrupted", "vehicle"), (s["sitl"]["ended_by"], stderr)
    assert s["sitl"]["links"]["ground"]["messages_rx"] > 0  # MAVProxy talked back and was tolerated
