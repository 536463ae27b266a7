"""u-blox UBX from a serial port, a TCP stream or a file, framed here and parsed by ``pyubx2`` into
decoded items (the receiver the companion owns; ``companion.gnss.ubx`` decodes, this opens and reads).

    for item in ubx_items(open_stream("tcp:127.0.0.1:5000")): ...  # epoch, PVT or ephemeris

Stream URLs: a file path, ``serial:/dev/ttyACM0:115200``, ``tcp:HOST:PORT``. The framing is ours, not
pyubx2's, so that damage costs only the damaged bytes: a frame whose checksum fails is not skipped
whole (its announced length may swallow the good frames after it: a truncated frame, a corrupted
length) but searched again from the byte after its sync characters; a length beyond any message the
decoder reads is refused at once. Every refusal is counted in ``decoder.counters``:
``junk_bytes`` (bytes outside any frame), ``bad_checksum``, ``bad_length``, ``bad_frame`` (a valid
checksum over a payload pyubx2 cannot parse), ``truncated_at_end`` (a frame cut by the end of the
stream), ``stalls`` (nothing for longer than the stream's timeout: waited on, not an end).
"""

from __future__ import annotations

import socket
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

from companion.errors import UserError
from companion.gnss.ubx import UbxDecoder, UbxItem

SYNC = b"\xb5\x62"
MAX_PAYLOAD = 16 + 32 * 255  # RXM-RAWX with 255 measurements, the largest message the decoder reads


class _SocketStream:
    """A TCP socket: ``read(n)`` gives what arrived (up to n bytes), ``b""`` at the end of the stream
    (the peer closed), ``None`` when nothing arrived within the timeout (a stall, not an end)."""

    def __init__(self, host: str, port: int, timeout_s: float) -> None:
        try:
            self.sock = socket.create_connection((host, port), timeout=timeout_s)
        except OSError as exc:
            raise UserError(f"tcp:{host}:{port}: cannot connect: {exc.strerror or exc}") from None

    def read(self, n: int) -> bytes | None:
        try:
            return self.sock.recv(n)
        except TimeoutError:
            return None

    def close(self) -> None:
        self.sock.close()


class _SerialStream:
    """A serial port: pyserial's empty read is its timeout (a serial line has no end), so ``None``; a
    read failing (the device unplugged, a pseudo-terminal's writer closed: EIO) is the stream's end,
    ``b""``, with the reason in ``ended``."""

    def __init__(self, port: Any) -> None:
        self.port = port
        self.ended = ""

    def read(self, n: int) -> bytes | None:
        try:
            return self.port.read(max(1, min(n, self.port.in_waiting))) or None
        except OSError as exc:  # pyserial's SerialException is one
            self.ended = f"the device is gone ({exc})"
            return b""

    def close(self) -> None:
        self.port.close()


def open_stream(url: str, timeout_s: float = 5.0) -> Any:
    """A readable binary stream for a file path, ``serial:DEVICE:BAUD`` or ``tcp:HOST:PORT``."""
    if url.startswith("tcp:"):
        try:
            _, host, port = url.split(":")
            return _SocketStream(host, int(port), timeout_s)
        except ValueError:
            raise UserError(f"{url!r}: expected tcp:HOST:PORT") from None
    if url.startswith("serial:"):
        try:
            _, dev, baud = url.rsplit(":", 2)
            import serial  # pyserial

            return _SerialStream(serial.Serial(dev, int(baud), timeout=timeout_s))
        except ValueError:
            raise UserError(f"{url!r}: expected serial:DEVICE:BAUD") from None
        except Exception as exc:  # noqa: BLE001 - pyserial's SerialException
            raise UserError(f"{url}: cannot open: {exc}") from None
    path = Path(url)
    if not path.is_file():
        raise UserError(f"{url}: no such file")
    return open(path, "rb")  # noqa: SIM115 - the caller closes it


def _checksum(body: bytes | bytearray) -> bytes:
    a = b = 0
    for x in body:
        a = (a + x) & 0xFF
        b = (b + a) & 0xFF
    return bytes((a, b))


def ubx_frames(stream: IO[bytes] | Any, counters: Counter[str],
               stop: Callable[[], bool] = lambda: False) -> Iterator[bytes]:
    """Whole UBX frames (sync to checksum) in arrival order, until the stream ends or ``stop()``."""
    buf = bytearray()
    stalled = False
    while not stop():
        chunk = stream.read(4096)
        if chunk is None:  # nothing within the timeout: wait on (counted once per stall)
            if not stalled:
                counters["stalls"] += 1
            stalled = True
            continue
        stalled = False
        if not chunk:
            break
        buf += chunk
        while True:
            i = buf.find(SYNC)
            if i < 0:
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                counters["junk_bytes"] += len(buf) - keep
                del buf[: len(buf) - keep]
                break
            if i:
                counters["junk_bytes"] += i
                del buf[:i]
            if len(buf) < 6:
                break
            n = int.from_bytes(buf[4:6], "little")
            if n > MAX_PAYLOAD:
                counters["bad_length"] += 1
                del buf[:2]  # search again after this sync
                continue
            if len(buf) < n + 8:
                break
            if _checksum(buf[2 : n + 6]) != buf[n + 6 : n + 8]:
                counters["bad_checksum"] += 1
                del buf[:2]  # a truncated frame's length may cover good frames: search again inside
                continue
            frame = bytes(buf[: n + 8])
            del buf[: n + 8]
            yield frame
    if buf.startswith(SYNC):
        counters["truncated_at_end"] += 1
    elif buf:
        counters["junk_bytes"] += len(buf)


def ubx_items(stream: IO[bytes] | Any, decoder: UbxDecoder | None = None,
              stop: Callable[[], bool] = lambda: False, final: bool = True,
              clock: Callable[[], float] | None = None) -> Iterator[UbxItem]:
    """Decoded items in arrival order; frames refused counted in ``decoder.counters``. ``final``: the
    stream's end is the data's (a file; ``UbxDecoder.end_of_stream``), not a connection's that the
    decoder outlives. ``clock``: a live stream's (``time.monotonic``): each frame's arrival time, by
    which an epoch after a gap on the receiver's own clock is released at once (``UbxDecoder``)."""
    from pyubx2 import UBXReader

    dec = decoder if decoder is not None else UbxDecoder()
    for frame in ubx_frames(stream, dec.counters, stop):
        arrival_s = clock() if clock is not None else None
        try:
            msg = UBXReader.parse(frame, validate=0)
        except Exception:  # noqa: BLE001 - a valid checksum over a payload pyubx2 cannot parse
            dec.counters["bad_frame"] += 1
            continue
        yield from dec.feed_all(msg, arrival_s)
    if final:
        dec.end_of_stream()
