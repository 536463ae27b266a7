"""A hostile receiver, live: a server on 127.0.0.1 streams the simulated receiver's UBX (40 epochs, the
receiver's time really jumping an hour ahead at epoch 30) with seeded damage between the frames, stalls
longer than the read timeout, and drops the connection twice (once in the middle of a frame); the
companion's reader thread (``RawReceiver``) must hand over every clean item exactly as the clean
stream decodes, count each damage by its reason, and reconnect."""

from __future__ import annotations

import io
import math
import os
import pickle
import socket
import struct
import threading
import time
from collections import Counter

import numpy as np
import pytest

from companion.gnss.observations import GnssEpoch
from companion.gnss.ubx import UbxDecoder
from companion.mission import load_mission
from companion.receiver.raw_receiver import RawReceiver
from companion.receiver.ubx_stream import ubx_items
from simvehicle import SimVehicle
from simvehicle.ubx import UbxEncoder, frame

RAWX, SFRBX, PVT = b"\x02\x15", b"\x02\x13", b"\x01\x07"
JUMP_EPOCH, JUMP_S = 30, 3600.0


def _payload(f: bytes) -> bytearray:
    return bytearray(f[6:-2])


def _reframe(f: bytes, payload: bytes | bytearray) -> bytes:
    return frame(f[2], f[3], bytes(payload))


def _patch(f: bytes, offset: int, fmt: str, *values: float) -> bytes:
    """The frame with ``values`` packed at ``offset`` of its payload, its checksum made valid again."""
    p = _payload(f)
    struct.pack_into("<" + fmt, p, offset, *values)
    return _reframe(f, p)


def _each_meas(f: bytes, offset: int, fmt: str, values: list[float]) -> bytes:
    n = _payload(f)[11]
    for i in range(n):
        f = _patch(f, 16 + 32 * i + offset, fmt, values[i % len(values)])
    return f


def _rawx_at(f: bytes, dt_s: float) -> bytes:
    return _patch(f, 0, "d", struct.unpack_from("<d", _payload(f), 0)[0] + dt_s)


@pytest.fixture(scope="module")
def epochs() -> list[list[bytes]]:
    """40 epochs (8 s at 5 Hz) of the canyon receiver: RXM-RAWX, RXM-SFRBX, NAV-SAT, NAV-PVT frames;
    from epoch 30 on, the receiver's time (rcvTow, iTOW) an hour later: a real jump."""
    sim = SimVehicle(load_mission("default", "canyon"), 4, 0)
    enc = UbxEncoder(sim.gnss.store)
    out: list[list[bytes]] = []
    while len(out) < 40:
        for raw in sim.advance(None, None).gnss_raw:
            out.append(enc.epoch_frames(raw))
    for fs in out[JUMP_EPOCH:]:
        for j, f in enumerate(fs):
            if f[2:4] == RAWX:
                fs[j] = _rawx_at(f, JUMP_S)
            elif f[2:4] in (PVT, b"\x01\x35"):  # NAV-PVT, NAV-SAT: iTOW (ms)
                fs[j] = _patch(f, 0, "I", struct.unpack_from("<I", _payload(f), 0)[0] + int(JUMP_S * 1000))
    return out[:40]


def _rawx(fs: list[bytes]) -> bytes:
    return next(f for f in fs if f[2:4] == RAWX)


def _same(a: object, b: object) -> bool:
    if isinstance(a, GnssEpoch) and isinstance(b, GnssEpoch):
        return a.t_gps_s == b.t_gps_s and all(
            np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True)
            for k in ("system", "prn", "pseudorange_m", "pseudorange_var_m2", "pseudorange_rate_m_s",
                      "cn0_dbhz", "elevation_deg", "azimuth_deg"))
    return pickle.dumps(a) == pickle.dumps(b)


def _t(fs: list[bytes]) -> float:
    from companion.gnss.timescale import gps_from_week_tow

    p = _payload(_rawx(fs))
    return gps_from_week_tow(struct.unpack_from("<H", p, 8)[0], struct.unpack_from("<d", p, 0)[0])


def _decode(data: bytes) -> tuple[list, Counter[str]]:
    dec = UbxDecoder()
    return list(ubx_items(io.BytesIO(data), dec)), dec.counters


def test_epoch_times_keep_order_a_lone_damaged_time_dropped_a_real_jump_kept(epochs):
    r = [_rawx(fs) for fs in epochs]
    week = struct.unpack_from("<H", _payload(r[2]), 8)[0]
    back, ahead = _patch(r[2], 8, "H", week - 1), _patch(r[3], 8, "H", week + 1)  # lone damaged weeks
    data = [r[0], r[1], r[1], r[2], back, r[3], ahead, r[4], _rawx_at(r[5], 3600.0), _rawx_at(r[6], 3600.0)]
    items, c = _decode(b"".join(data))
    assert [i.t_gps_s for i in items] == [*(_t(epochs[k]) for k in range(5)),
                                          _t(epochs[5]) + 3600.0, _t(epochs[6]) + 3600.0]
    assert (c["rawx_duplicate_epoch"], c["rawx_lone_time_back"], c["rawx_lone_time_ahead"],
            c["rawx_time_jump"], c["rawx_epochs"]) == (1, 1, 1, 1, 7)


def test_a_slow_receivers_epochs_are_all_kept_and_its_lone_damage_still_dropped(epochs):
    """A receiver logging every 30 s (each epoch 30 s after the last, more than MAX_EPOCH_STEP_S): once
    its interval shows (the second epoch, held for the third to confirm) every epoch is kept in order; a
    lone epoch a week back among them is still dropped and counted."""
    r = [_rawx(fs) for fs in epochs]
    t0 = _t(epochs[0])
    slow = [_rawx_at(r[0], 30.0 * k) for k in range(6)]  # the first epoch's measurements every 30 s
    week = struct.unpack_from("<H", _payload(slow[3]), 8)[0]
    items, c = _decode(b"".join([*slow[:3], _patch(slow[3], 8, "H", week - 1), *slow[3:]]))
    assert [i.t_gps_s for i in items] == [t0 + 30.0 * k for k in range(6)]
    assert (c["rawx_epochs"], c["rawx_lone_time_back"], c["rawx_time_jump"]) == (6, 1, 1)


def test_an_epoch_still_held_when_a_file_ends_is_counted_not_lost_unseen(epochs):
    """The last epoch of a file jumps an hour ahead: nothing after it can confirm it, so it is dropped
    and counted (rawx_unconfirmed_at_end); a live connection's end keeps it held for the next one."""
    r = [_rawx(fs) for fs in epochs]
    items, c = _decode(b"".join([r[0], r[1], _rawx_at(r[2], 3600.0)]))
    assert [i.t_gps_s for i in items] == [_t(epochs[0]), _t(epochs[1])]
    assert c["rawx_unconfirmed_at_end"] == 1 and c["rawx_epochs"] == 2
    dec = UbxDecoder()
    first = list(ubx_items(io.BytesIO(b"".join([r[0], r[1], _rawx_at(r[2], 3600.0)])), dec, final=False))
    later = list(ubx_items(io.BytesIO(_rawx_at(r[3], 3600.0)), dec))  # the next connection confirms it
    assert len(first) == 2 and [i.t_gps_s for i in later] == [_t(epochs[2]) + 3600.0, _t(epochs[3]) + 3600.0]
    assert dec.counters["rawx_time_jump"] == 1 and dec.counters["rawx_unconfirmed_at_end"] == 0


def test_absurd_cn0_doppler_and_receiver_fix_are_counted_not_used(epochs):
    rawx, pvt = _rawx(epochs[0]), next(f for f in epochs[0] if f[2:4] == PVT)
    n = _payload(rawx)[11]
    data = [_each_meas(rawx, 26, "B", [255]), _each_meas(_rawx_at(rawx, 0.2), 16, "f", [3e7]),
            _patch(pvt, 28, "i", 2_000_000_000), pvt]
    items, c = _decode(b"".join(data))
    assert len(items) == 2 and np.isnan(items[0].pseudorange_rate_m_s).all() and abs(items[1].lat_deg) < 90
    assert (c["rawx_invalid_cn0"], c["rawx_empty"], c["rawx_invalid_doppler"], c["pvt_out_of_range"]) == (
        n, 1, n, 1)


def test_a_truncated_frame_or_a_huge_length_costs_only_its_own_bytes(epochs):
    clean = b"".join(epochs[1]) + b"".join(epochs[2])
    want, _ = _decode(b"".join(epochs[0]) + clean)
    rawx = _rawx(epochs[0])
    for damage in (rawx[: len(rawx) // 2], b"\xb5\x62\x02\x15\xff\xff" + bytes(30)):
        items, c = _decode(b"".join(epochs[0]) + damage + clean)
        assert len(items) == len(want) and all(_same(a, b) for a, b in zip(items, want, strict=True))
        assert c["bad_checksum"] + c["bad_length"] >= 1


def test_a_stall_longer_than_the_read_timeout_is_waited_on_not_an_end(epochs):
    from companion.receiver.ubx_stream import open_stream
    from tests.gnss_helpers import serve_bytes_once

    data = b"".join(f for fs in epochs[:3] for f in fs)
    want, _ = _decode(data)
    dec = UbxDecoder()
    with serve_bytes_once(data, len(data) // 2 + 7, 0.6) as port:  # half, 0.6 s of silence, the rest
        items = list(ubx_items(open_stream(f"tcp:127.0.0.1:{port}", 0.2), dec))
    assert len(items) == len(want) and all(_same(a, b) for a, b in zip(items, want, strict=True))
    assert dec.counters["stalls"] == 2  # after each half (the server pauses after each piece)


def _hostile(epochs: list[list[bytes]]) -> tuple[list[tuple[str, object]], Counter[str]]:
    """The server's script (send bytes / pause / drop the connection) and the damage it holds."""
    rng = np.random.default_rng(11)
    script: list[tuple[str, object]] = []
    damage: Counter[str] = Counter()

    def send(b: bytes) -> None:
        script.append(("send", b))

    for k, fs in enumerate(epochs):
        junk = bytes(int(x) for x in rng.integers(0, 256, int(rng.integers(1, 40))) if x != 0xB5)
        send(junk)  # line noise between epochs, no sync character in it
        damage["junk_bytes"] += len(junk)
        rawx = _rawx(fs)
        if k == 19:  # a stall in the middle of a frame, longer than the read timeout (0.3 s)
            send(fs[0][:50])
            script.append(("pause", 0.8))
            send(b"".join(fs)[50:])
        else:
            send(b"".join(fs))
        if k == 2:  # a bad checksum
            p = _payload(rawx)
            p[40] ^= 0x10
            send(rawx[:6] + bytes(p) + rawx[-2:])
            damage["bad_checksum"] += 1
        elif k == 3:  # a truncated frame: its announced length swallows the next epoch's start
            send(rawx[: len(rawx) // 2])
            damage["bad_checksum"] += 1
        elif k == 4:  # a header announcing 65535 bytes
            send(b"\xb5\x62\x02\x15\xff\xff" + bytes(20))
            damage["bad_length"] += 1
        elif k == 5:  # pseudoranges NaN, inf, absurd; C/N0 255: no signal left
            n = _payload(rawx)[11]
            send(_each_meas(_rawx_at(rawx, 0.1), 0, "d", [math.nan, math.inf, 1e300, -2e7]))
            send(_each_meas(_rawx_at(rawx, 0.1), 26, "B", [255]))
            damage["rawx_invalid_pseudorange"] += n
            damage["rawx_invalid_cn0"] += n
            damage["rawx_empty"] += 2
        elif k == 7:  # Dopplers NaN, inf, absurd (valid pseudoranges): an epoch without rates
            send(_each_meas(_rawx_at(rawx, 0.1), 16, "f", [math.nan, math.inf, -math.inf, 3e7]))
            damage["rawx_invalid_doppler"] += _payload(rawx)[11]
        elif k == 9:  # numMeas beyond the payload, and numMeas 0
            send(_patch(rawx, 11, "B", 255))
            send(_reframe(rawx, _patch(_rawx_at(rawx, 0.1), 11, "B", 0)[6:22]))
            damage["bad_frame"] += 1
            damage["rawx_empty"] += 1
        elif k == 10:  # NAV-PVT: latitude 200°, fix type 9, 5 km/s north
            pvt = next(f for f in fs if f[2:4] == PVT)
            for off, fmt, v in ((28, "i", 2_000_000_000), (20, "B", 9), (48, "i", 5_000_000)):
                send(_patch(pvt, off, fmt, v))
            damage["pvt_out_of_range"] += 3
        elif k == 11:  # RXM-SFRBX: GPS random words, GPS without words, an unknown system
            words = [int(w) for w in rng.integers(0, 2**32, 10, dtype=np.uint64)]
            send(frame(2, 0x13, struct.pack("<8B10I", 0, 5, 0, 0, 10, 0, 2, 0, *words)))
            send(frame(2, 0x13, struct.pack("<8B", 0, 5, 0, 0, 0, 0, 2, 0)))
            send(frame(2, 0x13, struct.pack("<8BI", 42, 5, 0, 0, 1, 0, 2, 0, 7)))
            damage["lnav_refused"] += 2
            damage["sfrbx_not_decoded_42"] += 1
        elif k == 12:  # a lone epoch a week back, then one a week ahead (epoch 14)
            send(_patch(rawx, 8, "H", struct.unpack_from("<H", _payload(rawx), 8)[0] - 1))
            damage["rawx_lone_time_back"] += 1
        elif k == 14:
            send(_patch(rawx, 8, "H", struct.unpack_from("<H", _payload(rawx), 8)[0] + 1))
            damage["rawx_lone_time_ahead"] += 1
        elif k == 15:  # a time of week NaN
            send(_patch(rawx, 0, "d", math.nan))
            damage["rawx_bad_time"] += 1
        elif k == 16:  # the same epoch again
            send(rawx)
            damage["rawx_duplicate_epoch"] += 1
        elif k == 22:  # the connection dropped in the middle of a (repeated) frame; a new one accepted
            send(rawx[:100])
            script.append(("drop", None))
            damage["truncated_at_end"] += 1
            damage["disconnects"] += 1
        elif k == 26:  # dropped between frames
            script.append(("drop", None))
            damage["disconnects"] += 1
    damage["disconnects"] += 1  # the server gone for good at the end
    return script, damage


def _serve(srv: socket.socket, script: list[tuple[str, object]]) -> None:
    conn, _ = srv.accept()
    for what, arg in script:
        if what == "send":
            conn.sendall(arg)  # type: ignore[arg-type]
        elif what == "pause":
            time.sleep(arg)  # type: ignore[arg-type]  # the stall under test
        else:
            conn.close()
            conn, _ = srv.accept()
    conn.close()
    srv.close()  # the receiver is gone for good: the reader keeps trying, with backoff


def test_a_hostile_live_receiver_loses_no_clean_item_and_counts_every_damage(epochs, capfd):
    ref_dec = UbxDecoder()
    reference = list(ubx_items(io.BytesIO(b"".join(f for fs in epochs for f in fs)), ref_dec))
    assert sum(isinstance(i, GnssEpoch) for i in reference) == 40 and ref_dec.counters["rawx_time_jump"] == 1
    script, damage = _hostile(epochs)
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    server = threading.Thread(target=_serve, args=(srv, script), daemon=True)
    server.start()
    rx = RawReceiver(f"tcp:127.0.0.1:{srv.getsockname()[1]}", timeout_s=0.3, first_backoff_s=0.05)
    items: list = []
    deadline = time.monotonic() + 12.0
    try:
        while time.monotonic() < deadline and rx.counters().get("disconnects", 0) < 3:  # 2 drops, the end
            items += rx.drain()
            time.sleep(0.02)
        items += rx.drain()
        c = rx.counters()
        assert rx._thread.is_alive()  # still trying to reconnect
    finally:
        rx.close()
        server.join(timeout=5.0)
    # the epoch with its Dopplers damaged: its pseudoranges used, its rates not
    extra = [i for i in items if isinstance(i, GnssEpoch) and i.t_gps_s == _t(epochs[7]) + 0.1]
    assert len(extra) == 1 and np.isnan(extra[0].pseudorange_rate_m_s).all()
    rest = [i for i in items if i is not extra[0]]
    assert len(rest) == len(reference) and all(_same(a, b) for a, b in zip(rest, reference, strict=True))
    # every damage counted by its reason (beyond what the clean stream counts)
    got = Counter({k: v - ref_dec.counters.get(k, 0) for k, v in c.items() if isinstance(v, int)})
    got["lnav_refused"] = sum(v for k, v in got.items() if k.startswith("lnav_bad"))
    for k, v in damage.items():
        if k in ("junk_bytes", "bad_checksum", "bad_length"):  # a damaged frame's own bytes are junk too
            assert got[k] >= v, (k, got[k], v)
        else:
            assert got[k] == v, (k, got[k], v, got)
    assert got["stalls"] >= 1 and c["reconnects"] == 2 and c["rawx_time_jump"] == 1
    assert c["items"] == len(items) and not any(k.startswith("reader_errors") for k in c)
    err = capfd.readouterr().err.splitlines()
    assert err[:2] == [f"companion: receiver {rx.url}: the stream ended; reconnecting",
                       f"companion: receiver {rx.url}: reconnected"]


def _empty_rawx(f: bytes, dt_s: float) -> bytes:
    """The epoch's RXM-RAWX ``dt_s`` later with no measurement: what a receiver without a signal sends."""
    return _reframe(f, _patch(_rawx_at(f, dt_s), 11, "B", 0)[6:22])


def _paced(frames: list[tuple[float, bytes]]) -> tuple[list[list], Counter[str]]:
    """Each frame fed as it arrived on a live stream at its time (s): the items each one gave."""
    from pyubx2 import UBXReader

    dec = UbxDecoder()
    return [dec.feed_all(UBXReader.parse(f, validate=0), arrival_s=a) for a, f in frames], dec.counters


@pytest.mark.parametrize("gap_s", [3.0, 30.0])
def test_the_first_epoch_after_a_gap_on_the_receivers_own_clock_is_released_at_once(epochs, gap_s):
    """A 5 Hz receiver in a tunnel for ``gap_s``: its epochs without a signal decode to none, so the first
    one after is beyond the step limit. On a live stream its GPS time advanced as much as the stream's
    clock (arrival jitter 0-0.1 s, seeded): it comes out of its own frame, with its own data, not held
    until the next confirms it (one epoch late; a file, with no clock, still holds it)."""
    rng = np.random.default_rng(5)
    r = [_rawx(fs) for fs in epochs[:8]]
    t0 = _t(epochs[0])
    n_empty = int(round(gap_s / 0.2)) - 1
    stream = [*r[:4], *(_empty_rawx(r[3], 0.2 * (k + 1)) for k in range(n_empty)),
              *(_rawx_at(f, gap_s - 0.2) for f in r[4:])]
    t_of = [0.2 * k for k in range(4)] + [0.6 + 0.2 * (k + 1) for k in range(n_empty)] + [
        _t(epochs[k]) - t0 + gap_s - 0.2 for k in range(4, 8)]
    frames = [(1000.0 + t + 0.05 + float(rng.uniform(0.0, 0.1)), f)
              for t, f in zip(t_of, stream, strict=True)]
    out, c = _paced(frames)
    first = 4 + n_empty  # the first epoch after the gap
    assert all(len(o) == 1 for i, o in enumerate(out) if i < 4 or i >= first)
    assert all(o == [] for o in out[4:first])
    alone, _ = _decode(stream[first])  # its frame decoded on its own: the epoch's own data
    assert _same(out[first][0], alone[0]) and out[first][0].t_gps_s == _t(epochs[4]) + gap_s - 0.2
    assert [o[0].t_gps_s for o in out if o] == [_t(epochs[k]) for k in range(4)] + [
        _t(epochs[k]) + gap_s - 0.2 for k in range(4, 8)]
    assert (c["rawx_resumed"], c["rawx_epochs"], c["rawx_empty"]) == (1, 8, n_empty)
    assert c["rawx_time_jump"] + c["rawx_lone_time_back"] + c["rawx_lone_time_ahead"] == 0
    from_file, fc = _decode(b"".join(stream))  # the same bytes from a file: held for the next epoch
    assert [i.t_gps_s for i in from_file] == [o[0].t_gps_s for o in out if o]
    assert (fc["rawx_time_jump"], fc["rawx_resumed"]) == (1, 0)


def test_on_a_live_stream_lone_damaged_stamps_and_a_real_jump_are_still_held(epochs):
    """Paced at 5 Hz (arrival jitter 0-0.1 s): a lone week back, a lone week ahead and a duplicate are
    dropped and counted as from a file; a damaged week as the first epoch after a 3 s gap is held and
    dropped, the next (on the receiver's clock) released at once; the receiver's time jumping an hour
    while the stream's clock moved 0.2 s is held until the next epoch confirms it."""
    rng = np.random.default_rng(6)
    r = [_rawx(fs) for fs in epochs]
    t0 = _t(epochs[0])
    week = struct.unpack_from("<H", _payload(r[0]), 8)[0]
    gap = 3.0
    stream: list[tuple[float, bytes]] = []

    def at(t: float, f: bytes) -> None:
        stream.append((t + 0.05 + float(rng.uniform(0.0, 0.1)), f))

    for k in range(3):
        at(_t(epochs[k]) - t0, r[k])
    at(_t(epochs[3]) - t0, _patch(r[3], 8, "H", week - 1))  # lone week back
    at(_t(epochs[3]) - t0, r[3])
    at(_t(epochs[4]) - t0, _patch(r[4], 8, "H", week + 1))  # lone week ahead
    at(_t(epochs[4]) - t0, r[4])
    at(_t(epochs[4]) - t0, r[4])  # duplicate
    late = [_rawx_at(f, gap) for f in r[5:8]]  # after a 3 s gap, the first epoch's week damaged
    at(_t(epochs[5]) - t0 + gap, _patch(late[0], 8, "H", week + 1))
    at(_t(epochs[6]) - t0 + gap, late[1])
    at(_t(epochs[7]) - t0 + gap, late[2])
    at(_t(epochs[8]) - t0 + gap, _rawx_at(r[8], gap + 3600.0))  # the receiver's time jumps an hour
    at(_t(epochs[9]) - t0 + gap, _rawx_at(r[9], gap + 3600.0))
    out, c = _paced(stream)
    got = [i.t_gps_s for o in out for i in o]
    assert got == [*(_t(epochs[k]) for k in range(5)), _t(epochs[6]) + gap, _t(epochs[7]) + gap,
                   _t(epochs[8]) + gap + 3600.0, _t(epochs[9]) + gap + 3600.0]
    assert [len(o) for o in out[-4:]] == [1, 1, 0, 2]  # resumed at once; the jump held, then confirmed
    assert (c["rawx_lone_time_back"], c["rawx_lone_time_ahead"], c["rawx_duplicate_epoch"],
            c["rawx_resumed"], c["rawx_time_jump"], c["rawx_epochs"]) == (1, 2, 1, 1, 1, 9)


def _wait(cond: object, timeout_s: float = 20.0) -> bool:
    """Whether ``cond()`` came true within ``timeout_s`` (polled: the reader is another thread)."""
    deadline = time.monotonic() + timeout_s
    while not cond():  # type: ignore[operator]
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def test_a_serial_receiver_on_a_pseudo_terminal_reads_counts_and_comes_back(epochs, tmp_path, capfd):
    """``serial:DEVICE:BAUD`` for real: pyserial opens a pseudo-terminal's device through a link (as udev's
    /dev/serial/by-id names a USB receiver). The receiver's bytes written to the other side: every item
    decodes as from a file, in order, a damaged frame counted; the writer closing (the cable pulled) is
    one line and no reader error; a new device behind the same link (plugged back in) is reopened and
    read on with the same decoder."""
    link = tmp_path / "ublox"
    first = [b"".join(fs) for fs in epochs[:12]]
    rawx = _rawx(epochs[3])
    p = _payload(rawx)
    p[40] ^= 0x10
    first.insert(4, rawx[:6] + bytes(p) + rawx[-2:])  # a bad checksum
    second = [b"".join(fs) for fs in epochs[12:20]]
    reference, _ = _decode(b"".join(b"".join(fs) for fs in epochs[:20]))
    writer, device = os.openpty()
    link.symlink_to(os.ttyname(device))
    rx = RawReceiver(f"serial:{link}:115200", timeout_s=0.2, first_backoff_s=0.05)
    os.close(device)  # the reader holds its own
    items: list = []
    open_fds = [writer]
    try:
        for chunk in first:
            os.write(writer, chunk)
        n_first = len(_decode(b"".join(b"".join(fs) for fs in epochs[:12]))[0])  # the items before the cut
        assert _wait(lambda: items.extend(rx.drain()) or len(items) >= n_first), (len(items), rx.counters())
        os.close(open_fds.pop())  # the receiver gone
        assert _wait(lambda: rx.counters().get("disconnects", 0) == 1), rx.counters()
        writer2, device2 = os.openpty()  # plugged back in: another device, the same link
        open_fds += [writer2, device2]
        tmp = tmp_path / "ublox.new"
        tmp.symlink_to(os.ttyname(device2))
        os.replace(tmp, link)
        assert _wait(lambda: rx.counters().get("reconnects", 0) == 1), rx.counters()
        os.close(open_fds.pop())
        for chunk in second:
            os.write(writer2, chunk)
        assert _wait(lambda: items.extend(rx.drain()) or len(items) >= len(reference)), len(items)
        items += rx.drain()
        c = rx.counters()
    finally:
        rx.close()
        for fd in open_fds:
            os.close(fd)
    assert len(items) == len(reference) and all(_same(a, b) for a, b in zip(items, reference, strict=True))
    assert c["bad_checksum"] == 1 and c["rawx_epochs"] == 20 and c["disconnects"] == 1
    assert not any(k.startswith("reader_errors") for k in c), (c, capfd.readouterr().err)
    err = [line for line in capfd.readouterr().err.splitlines() if "companion: receiver" in line]
    url = f"companion: receiver serial:{link}:115200"
    assert len(err) == 2 and err[1] == f"{url}: reconnected", err  # pyserial's words vary with the race:
    assert err[0].startswith(f"{url}: the device is gone (") and err[0].endswith("); reconnecting"), err


@pytest.mark.parametrize(("url", "says"), [
    ("serial:{tmp}/none:115200", "cannot open: [Errno 2]"),  # no such device
    ("serial:{tmp}/plain:115200", "cannot open: Could not configure port"),  # not a terminal
    ("serial:{tmp}/none", "expected serial:DEVICE:BAUD"),
    ("serial:{tmp}/none:fast", "expected serial:DEVICE:BAUD"),
])
def test_a_serial_receiver_missing_or_misnamed_is_a_one_line_error(tmp_path, url, says):
    from companion.errors import UserError

    (tmp_path / "plain").write_bytes(b"")
    with pytest.raises(UserError) as err:
        RawReceiver(url.format(tmp=tmp_path))
    assert says in str(err.value) and "\n" not in str(err.value)
