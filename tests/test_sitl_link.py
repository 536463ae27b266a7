"""UdpLink over real loopback sockets: what cannot be used is counted, never raised."""

import hashlib
import socket

import numpy as np
import pytest

from companion.domain.samples import GnssFix
from companion.errors import UserError
from companion.mavlink import codec as codec
from companion.mavlink.lockstep import marker_time_us, response_time_us, step_marker, step_response
from companion.mavlink.udp_link import LinkConfig, UdpLink, read_signing_key

KEY = bytes(range(32))


@pytest.fixture
def links():
    made = []

    def make(**kw):
        link = UdpLink(LinkConfig(**kw))
        made.append(link)
        return link

    yield make
    for link in made:
        link.close()


def _raw(port, data):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(data, ("127.0.0.1", port))


def _heartbeat_frame(system_id=1):
    link = codec.new_link(system_id, 1)
    return bytearray(codec.pack(link, codec.encode_heartbeat("companion")))


def test_valid_frame_is_accepted_and_peer_learned(links):
    rx = links(accept_system_ids=frozenset({1}))
    tx = links(peer_port=rx.port, system_id=1)
    tx.send(codec.encode_heartbeat("vehicle"))
    msgs = rx.recv(timeout_s=1.0)
    assert [m.get_type() for m in msgs] == ["HEARTBEAT"]
    assert rx.peer == ("127.0.0.1", tx.port)
    rx.send(codec.encode_heartbeat("companion"))  # replies reach the learned peer
    assert [m.get_type() for m in tx.recv(timeout_s=1.0)] == ["HEARTBEAT"]


def test_garbage_bad_crc_unknown_and_wrong_system_id_are_counted(links):
    rx = links(accept_system_ids=frozenset({1}))
    _raw(rx.port, b"\x00not mavlink at all")
    _raw(rx.port, b"\xfd\x30\x00")  # a frame cut short
    bad_crc = _heartbeat_frame()
    bad_crc[-1] ^= 0xFF
    _raw(rx.port, bytes(bad_crc))
    unknown = _heartbeat_frame()
    unknown[7:10] = bytes((0x21, 0x43, 0x0E))  # message id 0x0E4321: not in the common dialect
    _raw(rx.port, bytes(unknown))
    _raw(rx.port, bytes(_heartbeat_frame(system_id=42)))
    _raw(rx.port, bytes(_heartbeat_frame(system_id=1)))
    got = []
    for _ in range(6):
        got += rx.recv(timeout_s=1.0)
    c = rx.counters
    assert [m.get_type() for m in got] == ["HEARTBEAT"]
    assert (c.datagrams_rx, c.bad_crc, c.unknown_message, c.wrong_system_id) == (6, 1, 1, 1)
    assert c.garbage >= 2


def test_signing_rejects_wrong_key_and_unsigned(links):
    rx = links(signing_key=KEY)
    wrong = links(peer_port=rx.port, signing_key=bytes(32), system_id=1, link_id=3)
    unsigned = links(peer_port=rx.port, system_id=1)
    good = links(peer_port=rx.port, signing_key=KEY, system_id=1, link_id=4)
    fix = codec.encode_gnss(GnssFix(1_000_000, 48.0, 11.0, 500.0, 3, 12))
    for sender in (wrong, unsigned, good):
        sender.send(fix)
    got = []
    for _ in range(3):
        got += rx.recv(timeout_s=1.0)
    assert [m.get_type() for m in got] == ["GPS_RAW_INT"]
    assert rx.counters.bad_signature == 2
    assert got[0].get_msgbuf()[2] & 0x01  # the signed flag
    assert got[0].get_msgbuf()[-13] == 4  # good's link id


def test_signed_frames_are_byte_equal_to_pymavlink_and_replays_are_refused(links):
    """The fast signed packer against pymavlink's own signing (same key, link id, timestamps),
    and a replayed datagram (same signature timestamp) counted, not accepted."""
    rx = links(signing_key=KEY, accept_system_ids=frozenset({7}))
    tx = links(peer_port=rx.port, signing_key=KEY, system_id=7, component_id=197, link_id=9)
    ref = codec.new_link(7, 197)
    ref.signing.secret_key, ref.signing.sign_outgoing, ref.signing.link_id = KEY, True, 9
    ref.signing.timestamp = tx.signer.timestamp
    sent: list[bytes] = []
    tx.tee = lambda frame, outgoing: sent.append(bytes(frame))
    fix = GnssFix(1_000_000, 48.0, 11.0, 500.0, 3, 12)
    msgs = [codec.encode_heartbeat("companion"), codec.encode_gnss(fix), step_response(1_250_000, 99)]
    for m in msgs:
        tx.send(m)
    expected = []
    for m in msgs:  # pack() signs and advances ref's timestamp; send() would advance its seq
        expected.append(bytes(m.pack(ref)))
        ref.seq += 1
    assert sent == expected
    got = []
    for _ in msgs:
        got += rx.recv(timeout_s=1.0)
    assert [m.get_type() for m in got] == ["HEARTBEAT", "GPS_RAW_INT", "TIMESYNC"]
    for m, frame in zip(got, sent, strict=True):
        assert m.get_msgbuf() == frame
    _raw(rx.port, sent[1])  # a replay: its timestamp is not newer than the stream's last
    assert rx.recv(timeout_s=1.0) == [] and rx.counters.bad_signature == 1


def test_port_in_use_is_one_line_user_error(links):
    taken = links()
    with pytest.raises(UserError, match=f"UDP port {taken.port} .* already in use"):
        UdpLink(LinkConfig(bind_port=taken.port))


def test_loss_injection_is_seeded_and_counted(links):
    def run(seed):
        rx = links()
        tx = UdpLink(LinkConfig(peer_port=rx.port, drop_probability_tx=0.3), np.random.default_rng(seed))
        for _ in range(200):
            tx.send(codec.encode_heartbeat("vehicle"))
        tx.close()
        return tx.counters.dropped_tx, tx.counters.datagrams_tx

    a, b = run(7), run(7)
    assert a == b and a[0] + a[1] == 200
    assert 30 < a[0] < 90  # ~60 expected (binomial 200, 0.3; sd 6.5)


def test_lockstep_marker_and_response_round_trip_through_bytes():
    link = codec.new_link(1, 1)
    parser = codec.new_link(1, 2)
    marker = parser.parse_buffer(codec.pack(link, step_marker(1_250_000)))[0]
    response = parser.parse_buffer(codec.pack(link, step_response(1_250_000, 99)))[0]
    assert marker_time_us(marker) == 1_250_000 and response_time_us(marker) is None
    assert response_time_us(response) == 1_250_000 and marker_time_us(response) is None


def test_signing_key_file(tmp_path):
    hexkey = tmp_path / "hex.key"
    hexkey.write_text(KEY.hex())
    assert read_signing_key(hexkey) == KEY
    phrase = tmp_path / "phrase.key"
    phrase.write_text("correct-horse\n")
    assert read_signing_key(phrase) == hashlib.sha256(b"correct-horse").digest()
    from MAVProxy.modules.mavproxy_signing import SigningModule

    assert read_signing_key(phrase) == SigningModule.passphrase_to_key(None, "correct-horse")  # `signing key`
    for untypable in ("correct horse", "caf\u00e9"):  # MAVProxy keeps one word; it encodes ASCII
        (tmp_path / "bad.key").write_text(untypable, encoding="utf-8")
        with pytest.raises(UserError, match="one word of printable ASCII"):
            read_signing_key(tmp_path / "bad.key")
    (tmp_path / "empty.key").write_text("")
    with pytest.raises(UserError, match="empty"):
        read_signing_key(tmp_path / "empty.key")
    with pytest.raises(UserError, match="cannot read"):
        read_signing_key(tmp_path / "missing.key")


def test_fresh_run_key_is_a_passphrase_mavproxy_can_take(tmp_path):
    from MAVProxy.modules.mavproxy_signing import SigningModule

    from simvehicle.harness.sitl.launcher import write_fresh_key

    keys = []
    for name in ("a.key", "b.key"):
        write_fresh_key(tmp_path / name)
        word = (tmp_path / name).read_text().strip()
        assert len(word.split()) == 1 and len(word) == 43
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o600
        keys.append(read_signing_key(tmp_path / name))
        assert keys[-1] == SigningModule.passphrase_to_key(None, word)  # `signing key <word>` in MAVProxy
    assert keys[0] != keys[1]


def _normalised(value):
    if isinstance(value, bytes | str):
        return value.encode() if isinstance(value, str) else value
    return list(value) if isinstance(value, list | tuple) else value


def test_fast_datagram_parser_equals_pymavlink_and_resynchronises():
    """Unsigned links parse with companion.mavlink.frames: every field, the sender's system id and
    the frame bytes equal pymavlink's; garbage between frames costs only itself."""
    from companion.domain.samples import ImuSample, NavEstimate
    from companion.mavlink.frames import parse_datagram

    sender = codec.new_link(7, 197)
    est = NavEstimate(1_020_000, np.array([1.5, -2.25, -30.0]), np.array([0.1, 0.2, -0.3]), np.zeros(3),
                      np.arange(9.0) * 0.01, 0.75, 1.25, "second-order")
    msgs = [codec.encode_imu(ImuSample(1_000_000, np.array([0.1, -0.2, -9.8]), np.array([0.01, 0.0, -0.02]))),
            codec.encode_odometry(est), *codec.encode_belief(est), step_response(1_000_000, 5),
            codec.encode_gnss(GnssFix(1_000_000, 48.1, 11.5, 520.25, 3, 12)),
            codec.encode_heartbeat("companion")]
    frames = [codec.pack(sender, m) for m in msgs]
    data = b"".join(frames[:3]) + b"\x00\x01junk" + b"".join(frames[3:])
    views, skipped = parse_datagram(data)
    reference = codec.new_link(1, 1).parse_buffer(b"".join(frames))
    assert [v.get_type() for v in views] == [m.get_type() for m in reference]
    assert skipped == ["garbage"]
    for view, ref, frame in zip(views, reference, frames, strict=True):
        assert view.get_srcSystem() == 7 and bytes(view.get_msgbuf()) == frame == bytes(ref.get_msgbuf())
        for name in ref.get_fieldnames():
            np.testing.assert_equal(_normalised(getattr(view, name)), _normalised(getattr(ref, name)),
                                    err_msg=f"{ref.get_type()}.{name}")
    fast, slow = codec.decode_odometry(views[1]), codec.decode_odometry(reference[1])
    np.testing.assert_equal([fast.p_ned_m, fast.cov_diag], [slow.p_ned_m, slow.cov_diag])


def test_fast_packer_is_byte_equal_to_pymavlink():
    from companion.domain.samples import AttitudeSample, ImuSample
    from companion.mavlink.frames import pack_frame

    reference = codec.new_link(3, 191)
    msgs = [codec.encode_imu(ImuSample(5_000, np.array([0.0, 0.25, -9.81]), np.zeros(3))),
            codec.encode_attitude(AttitudeSample(5_000, np.array([0.5, 0.5, -0.5, 0.5]))),
            codec.encode_named_value(7_000, "GNSS_BETA", 0.25), codec.encode_heartbeat("vehicle"),
            step_marker(0)]  # all-zero payload: MAVLink 2 keeps one byte
    for seq, msg in enumerate(msgs * 60):  # seq wraps at 256
        assert pack_frame(msg, seq & 0xFF, 3, 191) == codec.pack(reference, msg)
