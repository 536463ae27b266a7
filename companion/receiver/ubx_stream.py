"""u-blox UBX from a serial port, a TCP stream or a file, through ``pyubx2``, into decoded items (the
receiver the companion owns; ``companion.gnss.ubx`` decodes, this opens and reads).

    for item in ubx_items(open_stream("tcp:127.0.0.1:5000")): ...  # epoch, PVT or ephemeris

Stream URLs: a file path, ``serial:/dev/ttyACM0:115200``, ``tcp:HOST:PORT``. Malformed frames are
skipped and counted by pyubx2's error handling (``quitonerror=ERR_LOG`` semantics: counted here).
"""

from __future__ import annotations

import socket
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from companion.errors import UserError
from companion.gnss.ubx import UbxDecoder, UbxItem


class _SocketStream:
    """A TCP socket with the ``read(n)`` pyubx2 needs."""

    def __init__(self, host: str, port: int, timeout_s: float) -> None:
        try:
            self.sock = socket.create_connection((host, port), timeout=timeout_s)
        except OSError as exc:
            raise UserError(f"tcp:{host}:{port}: cannot connect: {exc.strerror or exc}") from None

    def read(self, n: int) -> bytes:
        out = b""
        while len(out) < n:
            try:
                chunk = self.sock.recv(n - len(out))
            except TimeoutError:
                return out
            if not chunk:
                return out
            out += chunk
        return out

    def close(self) -> None:
        self.sock.close()


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

            return serial.Serial(dev, int(baud), timeout=timeout_s)
        except ValueError:
            raise UserError(f"{url!r}: expected serial:DEVICE:BAUD") from None
        except Exception as exc:  # noqa: BLE001 - pyserial's SerialException
            raise UserError(f"{url}: cannot open: {exc}") from None
    path = Path(url)
    if not path.is_file():
        raise UserError(f"{url}: no such file")
    return open(path, "rb")  # noqa: SIM115 - the caller closes it


def ubx_items(stream: IO[bytes] | Any, decoder: UbxDecoder | None = None) -> Iterator[UbxItem]:
    """Decoded items in arrival order; unreadable frames counted in ``decoder.counters``."""
    from pyubx2 import UBX_PROTOCOL, UBXReader

    dec = decoder if decoder is not None else UbxDecoder()
    reader = UBXReader(
        stream,
        protfilter=UBX_PROTOCOL,
        quitonerror=2,
        validate=1,
        errorhandler=lambda exc: dec.counters.update(["bad_frame"]),
    )
    while True:
        try:
            raw, msg = reader.read()
        except Exception:  # noqa: BLE001 - pyubx2 raises on a frame it cannot parse
            dec.counters["bad_frame"] += 1
            continue
        if raw is None:
            return
        if msg is None:
            continue
        yield from dec.feed_all(msg)  # counted, never raised
