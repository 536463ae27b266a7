"""The ``--master`` path against hostile or unlucky input, without a real autopilot: the stream
scanner, signing, the UDP peer table, the one clock rule on the boot time, the checked
SYSTEM_TIME / fixes / frame, bounded comparison memory, truthful endings and one-line errors.
Known answers and exact equivalences (forged frames refused = the same estimate as without them)."""

from __future__ import annotations

import math
import socket
import threading
import time

import numpy as np
import pytest
from autopilot_stream import HOME, gps, heartbeat, imu, packed, stream, system_time
from pymavlink.dialects.v20 import common as mavlink

from companion.autopilot.compare import LiveComparison
from companion.autopilot.connection import MavConnection, PeerPolicy, open_connection, parse_connection
from companion.autopilot.discovery import DiscoveryConfig
from companion.autopilot.node import AutopilotCompanion, CompanionConfig
from companion.autopilot.service import serve
from companion.errors import UserError
from companion.mavlink.frames import StreamScanner, pack_frame, parse_datagram
from companion.mavlink.signing import Signer, signing_timestamp_now
from gcs_tools import cli

KEY = bytes(range(32))


def _frame(msg, system_id=1, component_id=1, seq=0, signer: Signer | None = None) -> bytes:
    frame = pack_frame(msg, seq & 0xFF, system_id, component_id, signed=signer is not None)
    return frame if signer is None else signer.sign(frame)


def _genuine(n: int) -> list[bytes]:
    out = []
    for k in range(n):
        t = k * 20_000
        msg = [imu(t), gps(t), heartbeat(), mavlink.MAVLink_statustext_message(6, b"EKF2 ok")][k % 4]
        out.append(_frame(msg, seq=k))
    return out


# --- the stream scanner ------------------------------------------------------------------------
def test_stream_scanner_resynchronises_on_junk_and_loses_no_genuine_frame():
    """Genuine frames with junk between them (random bytes, false magic bytes announcing long
    frames, truncated frames), fed in random chunks down to one byte: every genuine frame comes
    out, in order, exactly once."""
    rng = np.random.default_rng(3)
    genuine = _genuine(400)
    blob = bytearray()
    for k, frame in enumerate(genuine):
        blob += frame
        r = k % 5
        if r == 0:
            blob += rng.integers(0, 256, int(rng.integers(1, 60)), dtype=np.uint8).tobytes()
        elif r == 1:
            blob += bytes((0xFD, 0xFF, 0, 0)) + rng.integers(0, 256, 20, dtype=np.uint8).tobytes()  # "255 B"
        elif r == 2:
            blob += genuine[(k + 7) % len(genuine)][:9]  # a frame cut short
        elif r == 3:
            blob += bytes((0xFE, 0x30))  # a MAVLink 1 start with nothing behind it
    scanner = StreamScanner("ardupilotmega")
    got, skipped = [], []
    pos = 0
    while pos < len(blob):
        n = int(rng.integers(1, 300))
        views, reasons = scanner.feed(bytes(blob[pos:pos + n]))
        got += [v.get_msgbuf() for v in views]
        skipped += reasons
        pos += n
    assert got == genuine
    assert len(skipped) >= 300 and set(skipped) <= {"garbage", "bad_crc", "unknown_msgid", "truncated"}
    assert len(scanner._buffer) < 300  # bounded: at most one frame waits


def test_unknown_message_ids_are_skipped_whole_when_a_frame_follows():
    unknown = bytearray(_frame(heartbeat()))
    unknown[7:10] = bytes((0x21, 0x43, 0x0E))  # an id no dialect has (PX4's development messages)
    datagram = bytes(unknown) + _frame(heartbeat(), seq=1) + bytes(unknown)
    views, skipped = parse_datagram(datagram, "ardupilotmega")
    assert [v.get_type() for v in views] == ["HEARTBEAT"] and skipped == ["unknown_msgid", "unknown_msgid"]
    s = StreamScanner()
    views, skipped = s.feed(datagram + _frame(heartbeat(), seq=2))
    assert len(views) == 2 and skipped.count("unknown_msgid") == 2


# --- signing -----------------------------------------------------------------------------------
def test_signer_verdicts_and_a_forged_far_future_frame_cannot_cut_the_stream():
    sender, receiver, other = Signer(KEY, link_id=3), Signer(KEY), Signer(bytes(32), link_id=3)
    hb = heartbeat()
    first = _frame(hb, signer=sender)
    assert receiver.verdict(first, 1, 1) == "ok"
    assert receiver.verdict(first, 1, 1) == "replayed"
    assert receiver.verdict(_frame(hb), 1, 1) == "unsigned"
    other.timestamp = 2**47  # same stream, another key, far future
    assert receiver.verdict(_frame(hb, signer=other), 1, 1) == "bad_signature"
    assert receiver.verdict(_frame(hb, signer=sender), 1, 1) == "ok"  # the genuine stream goes on
    old = Signer(KEY, link_id=9, timestamp=signing_timestamp_now() - 10_000_000)  # 100 s old recording
    assert receiver.verdict(_frame(hb, signer=old), 1, 1) == "replayed"


# --- the connection ----------------------------------------------------------------------------
def _udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _recv_all(conn: MavConnection, wanted: int, timeout_s: float = 3.0) -> list:
    got: list = []
    deadline = time.monotonic() + timeout_s
    while len(got) < wanted and time.monotonic() < deadline:
        got += conn.recv(0.05)
    return got


def test_a_busy_udp_port_is_refused_not_shared():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("127.0.0.1", 0))
        port = holder.getsockname()[1]
        with pytest.raises(UserError, match=f"UDP port {port} is already in use"):
            open_connection(f"udpin:127.0.0.1:{port}", 1, 197, None)


def test_udpin_answers_only_its_autopilots_addresses_bounded_and_forgotten():
    port = _udp_port()
    conn = open_connection(f"udpin:127.0.0.1:{port}", 1, 197, None, peers=PeerPolicy(max_peers=2,
                                                                                      peer_timeout_s=0.5))
    senders = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(60)]
    try:
        for k, s in enumerate(senders):  # 60 addresses: junk, and frames of other systems
            s.sendto(b"\xfd\x10junk" if k % 2 else _frame(heartbeat(), system_id=50 + k), ("127.0.0.1", port))
        got = _recv_all(conn, 30)
        assert len(got) == 30 and conn.counters["garbage"] == 30
        assert not conn.send(heartbeat()) and conn.counters["send_no_peer"] == 1  # nobody is ours yet
        for s in senders[:4]:  # four addresses send as the autopilot; the node says it is ours
            s.sendto(_frame(imu(1000)), ("127.0.0.1", port))
        now = time.monotonic()
        for msg in _recv_all(conn, 4):
            conn.note_peer(msg, now)
        assert len(conn.peer_addresses) == 2 and conn.counters["peers_refused"] == 2  # bounded
        assert conn.send(heartbeat())
        for s in senders[:2]:
            s.settimeout(1.0)
            assert parse_datagram(s.recv(512))[0][0].get_type() == "HEARTBEAT"
        time.sleep(0.6)
        assert not conn.send(heartbeat()) and conn.counters["peers_expired"] == 2  # silent: forgotten
    finally:
        conn.close()
        for s in senders:
            s.close()


def test_unsendable_messages_are_counted_not_raised():
    port = _udp_port()
    conn = open_connection(f"udpout:127.0.0.1:{port}", 1, 197, None)
    try:
        bad = mavlink.MAVLink_gps_input_message(0, 0, 0, 0, 70_000, 3, 0, 0, 0.0, 1, 1, 0, 0, 0, 0, 0, 0, 10)
        assert not conn.send(bad) and conn.counters["unsendable_GPS_INPUT"] == 1  # week beyond uint16
        assert conn.send(heartbeat()) and conn.counters["sent"] == 1
    finally:
        conn.close()


def test_signed_link_refuses_unsigned_wrong_key_and_replayed_frames_and_signs_its_own():
    port = _udp_port()
    conn = open_connection(f"udpin:127.0.0.1:{port}", 1, 197, None, signing_key=KEY)
    autopilot = Signer(KEY, link_id=1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        good = _frame(heartbeat(), signer=autopilot)
        s.sendto(b"".join((_frame(heartbeat()), _frame(heartbeat(), signer=Signer(bytes(32))), good, good)),
                 ("127.0.0.1", port))
        got = _recv_all(conn, 1)
        assert len(got) == 1
        c = conn.counters
        assert (c["unsigned"], c["bad_signature"], c["replayed"], c["received"]) == (1, 1, 1, 1)
        conn.note_peer(got[0], time.monotonic())  # the node found it is the autopilot's
        assert conn.send(heartbeat())
        s.settimeout(1.0)
        reply = s.recv(512)
        assert autopilot.verdict(reply, 1, 197) == "ok"  # signed with the key
    conn.close()


def test_a_refused_tcp_host_is_one_quiet_line(capfd):
    port = _udp_port()  # nobody listens on this TCP port
    t0 = time.monotonic()
    with pytest.raises(UserError, match=r"cannot connect: Connection refused"):
        MavConnection(parse_connection(f"tcp:127.0.0.1:{port}"), 1, 197, connect_retries=2)
    assert 0.9 < time.monotonic() - t0 < 3.0
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # no "sleeping" lines


def test_tcp_stream_with_junk_delivers_every_frame_and_reconnects():
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    genuine = _genuine(200)
    junk = bytes((0xFD, 0xF0, 0, 0, 1)) + b"noise" * 10

    def serve_once() -> None:
        peer, _ = server.accept()
        for frame in genuine:
            peer.sendall(junk[: len(frame) % len(junk)] + frame)
        peer.close()

    worker = threading.Thread(target=serve_once)
    worker.start()
    conn = MavConnection(parse_connection(f"tcp:127.0.0.1:{server.getsockname()[1]}"), 1, 197)
    try:
        got = _recv_all(conn, len(genuine))
        worker.join()
        assert [bytes(m.get_msgbuf()) for m in got] == genuine
        assert conn.counters["garbage"] > 0
        worker = threading.Thread(target=serve_once)
        worker.start()
        got = _recv_all(conn, len(genuine))  # the peer closed: reconnected, all again
        worker.join()
        assert len(got) == len(genuine)
        assert conn.counters["disconnects"] >= 1 and conn.counters["reconnects"] == 1
    finally:
        conn.close()
        server.close()


# --- the node: one clock rule, checked inputs --------------------------------------------------
class _Conn:
    """Stands in for MavConnection: records what the node sends."""

    exact_arrivals = True  # the simulated arrival times are exact: the datagram rule applies

    def __init__(self) -> None:
        self.sent: list = []
        self.counters: dict = {}

    def arrival_us(self, msg) -> None:
        return None  # the node's own clock (the simulated time) is the arrival time

    def send(self, msg) -> bool:
        self.sent.append(msg)
        return True

    def note_peer(self, msg, now_s) -> None:
        pass

    def set_source(self, system_id: int, component_id: int) -> None:
        pass


def _run(items, tmp_path, **config) -> AutopilotCompanion:
    node = AutopilotCompanion(CompanionConfig(master="udpin::14550", out_dir=tmp_path, **config), _Conn())  # type: ignore[arg-type]
    for t, msg in items:
        node.handle(msg, t)
        node.tick(t)
    return node


def _final(node: AutopilotCompanion) -> np.ndarray:
    assert node.nav is not None
    est = node.nav.estimate()
    assert est is not None
    return np.asarray(est.p_ned_m)


def test_forged_stamps_are_refused_and_the_estimate_is_exactly_as_without_them(tmp_path):
    """A lone HIGHRES_IMU an hour ahead, ten stamped 0.9 s ahead in one burst (pulling 5 m/s² east),
    three 8 s back: all refused by the clock rule; the Navigator sees exactly the genuine
    sequence (same estimate to 1e-9), no reboot, no sample of the genuine stream lost."""
    clean = list(stream(0.0, 12.0))
    forged = []
    base_us = 8_000_000
    forged.append((7.01, packed(imu(base_us + 3_600_000_000))))
    forged += [(8.01, packed(imu(base_us + 900_000 + k * 20_000, acc_y=5.0))) for k in range(10)]
    forged += [(9.01 + k * 0.001, packed(imu(1_000_000 + k * 20_000))) for k in range(3)]  # 8 s back
    hostile = sorted(clean + forged, key=lambda item: item[0])
    a, b = _run(clean, tmp_path / "a"), _run(hostile, tmp_path / "b")
    np.testing.assert_allclose(_final(b), _final(a), atol=1e-9)
    assert b.nav_counters() == a.nav_counters() and b.nav_counters()["imu_used"] > 500
    assert b.counters["rejected_clock_highres_imu"] == 14 and b.counters["autopilot_reboots"] == 0


def test_a_reboot_needs_a_lasting_run_of_agreeing_stamps(tmp_path):
    before = list(stream(0.0, 6.0))
    after = [(6.02 + t, m) for t, m in stream(0.0, 3.0)]  # its boot time starts again at 0
    node = _run(before + after, tmp_path)
    assert node.counters["autopilot_reboots"] == 1 and node.epoch == 1
    assert node.counters["stream_requests"] == 2  # asked again
    assert node.nav is not None and node.nav.counters()["imu_used"] > 120  # a fresh Navigator runs


def test_the_frame_needs_agreeing_fixes_and_far_fixes_never_reach_the_filter(tmp_path):
    items = list(stream(0.0, 8.0))
    for t_s in (1.05, 6.0):  # the first fix after discovery (t = 1 s), and one later: 5,000 km south
        k = next(i for i, (t, m) in enumerate(items) if t >= t_s and m.get_type() == "GPS_RAW_INT")
        items[k] = (items[k][0], packed(gps(round(items[k][0] * 1e6), lat=HOME[0] - 45.0)))
    node = _run(items, tmp_path)
    assert node.frames.source == "first good fix"
    assert abs(node.frame.home_lat_deg - HOME[0]) < 1e-9  # type: ignore[union-attr]
    assert node.frames.counters["rejected_gnss_far_from_home"] == 1
    assert np.linalg.norm(_final(node)) < 1.0  # at home, not pulled
    summary = node.summary(8.0)
    assert summary["samples"]["rejected"]["rejected_gnss_far_from_home"] == 1


def test_a_forged_origin_far_from_the_fixes_is_not_the_frame(tmp_path):
    far = round((HOME[0] + 10) * 1e7)  # 1,100 km north
    origin = mavlink.MAVLink_gps_global_origin_message(far, round(HOME[1] * 1e7), 0, 0)
    items = sorted([(1.0001, packed(origin)), *stream(0.0, 3.0)], key=lambda i: i[0])  # just discovered
    node = _run(items, tmp_path)
    assert node.frames.source == "first good fix"
    assert node.frames.counters["rejected_origin_far_from_fixes"] == 1


def test_a_spoofed_system_time_is_refused_and_the_gps_input_feed_goes_on(tmp_path):
    items = list(stream(0.0, 8.0))
    items.append((5.001, packed(system_time(5_000_000, unix_us=2**63 - 1))))  # the 2^63
    items.append((6.001, packed(system_time(6_000_000, unix_us=2**62))))
    node = _run(sorted(items, key=lambda i: i[0]), tmp_path, feed="gps-input")
    assert node.translator.counters["rejected_system_time_range"] == 2
    sent = [m for m in node.conn.sent if m.get_type() == "GPS_INPUT"]  # type: ignore[attr-defined]
    assert len(sent) > 50 and not any(k.startswith(("handler_error", "unsendable")) for k in node.counters)
    assert {m.time_week for m in sent[-30:]} == {2288}  # UNIX0 (2023-11-14) + 8 s: the genuine clock


def test_a_lost_autopilot_ends_the_run_with_a_reason(tmp_path):
    port = _udp_port()
    discovery = DiscoveryConfig(election_s=0.1, heartbeat_timeout_s=0.3, lost_timeout_s=0.6)
    conn = open_connection(f"udpin:127.0.0.1:{port}", 1, 197, None)
    node = AutopilotCompanion(CompanionConfig(master=f"udpin:127.0.0.1:{port}", out_dir=tmp_path,
                                              discovery=discovery), conn)

    def autopilot() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for k in range(8):  # 0.4 s of HEARTBEATs, then silence for good
                s.sendto(_frame(heartbeat(), seq=k), ("127.0.0.1", port))
                time.sleep(0.05)

    sender = threading.Thread(target=autopilot)
    sender.start()
    start = time.monotonic()
    try:
        reason = serve(node, start)
    finally:
        sender.join()
        conn.close()
    assert reason is not None and "silent" in reason and "lost" in reason and node.errors == [reason]
    assert 0.9 < time.monotonic() - start < 5.0


# --- bounded memory ----------------------------------------------------------------------------
def test_the_comparison_keeps_bounded_memory_and_known_statistics():
    """25,000 comparisons kept as at most 500 error vectors: the median and max of a known error
    series stay right, the count exact."""
    cmp_ = LiveComparison(max_gap_us=200_000, max_errors=500)
    for k in range(50_001):
        t = k * 40_000
        cmp_.estimate(t, (1.0, 0.0, 0.0), 0.5 + 0.5 * (k % 2))
        if k % 2:  # a reference between two estimates: interpolated exactly; error (1, 3·frac, 0)
            frac = (k % 100) / 100
            cmp_.reference_global(t - 20_000, (0.0, -3.0 * frac, 0.0))
    found = cmp_.errors(None)
    assert found is not None
    block, how = found
    assert how == "global" and block["error_horizontal_m"]["count"] == 25_000
    kept = cmp_.global_errors.errors_ned_m()
    assert len(kept) <= 500 and cmp_.global_errors.decimation == 64
    expected = np.hypot(1.0, 3.0 * (np.arange(1, 100, 2) / 100))  # the 50 distinct errors, evenly
    assert block["error_horizontal_m"]["median"] == pytest.approx(np.median(expected), abs=0.05)
    assert block["error_horizontal_m"]["max"] == pytest.approx(expected.max(), abs=1e-6)
    beta = cmp_.beta_summary()
    assert beta["count"] == 50_001 and beta["min"] == 0.5 and beta["max"] == 1.0
    assert cmp_.beta.counts.size == 10_000  # fixed size


# --- one-line errors ---------------------------------------------------------------------------
@pytest.mark.parametrize(("extra", "why"), [
    (["--discovery-timeout-s", "nan"], "--discovery-timeout-s nan: must be a positive number"),
    (["--discovery-timeout-s", "-1"], "--discovery-timeout-s -1.0: must be a positive number"),
    (["--lost-timeout-s", "nan"], "--lost-timeout-s nan"),
    (["--lost-timeout-s", "1"], "--lost-timeout-s 1.0: must be a number above 3 s"),
    (["--target-system", "0"], "--target-system 0: must be 1..255"),
    (["--setup-signing"], "--setup-signing needs --signing-key-file"),
])
def test_bad_options_are_one_line_errors(tmp_path, capsys, extra, why):
    assert cli.main(["companion", "--master", "udpin::1", "--out", str(tmp_path / "o"), "--no-telemetry",
                     *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("beliefnav: error:") and why in err and len(err.strip().splitlines()) == 1, err


def test_bad_out_directories_and_busy_ports_are_one_line_errors(tmp_path, capsys):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("127.0.0.1", 0))
        busy = holder.getsockname()[1]
        cases = ((a_file, "udpin::1", "exists and is not a directory"),
                 (a_file / "sub", "udpin::1", "cannot create the directory"),
                 (tmp_path / "ok", f"udpin:127.0.0.1:{busy}", f"UDP port {busy} is already in use"))
        for out, master, why in cases:
            assert cli.main(["companion", "--master", master, "--out", str(out), "--no-telemetry"]) == 2
            err = capsys.readouterr().err
            assert err.startswith("beliefnav: error:") and why in err and len(err.strip().splitlines()) == 1


def test_unsigned_on_a_network_link_is_a_loud_warning(tmp_path, capsys):
    from companion.autopilot.service import security_note

    config = CompanionConfig(master="udpin:0.0.0.0:14550", out_dir=tmp_path)
    note = security_note(config)
    assert note["signing"] is False and note["loopback"] is False and "signing is OFF" in note["warning"]
    assert security_note(CompanionConfig(master="udpin:127.0.0.1:14550", out_dir=tmp_path))["warning"] is None
    signed = CompanionConfig(master="tcp:10.0.0.2:5760", out_dir=tmp_path, signing_key=KEY)
    assert security_note(signed)["warning"] is None and math.isnan(float("nan"))
