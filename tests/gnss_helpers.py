"""The synthetic constellation of ``gcs_tools.gnss.synthetic`` under the names the tests use, and a
receiver's byte stream served over TCP."""

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from gcs_tools.gnss.synthetic import (  # noqa: F401
    BASE,
    CLOCKS_M,
    KLOBUCHAR,
    RX_ECEF,
    T0,
    TOE_SOW,
    WEEK,
    constellation,
    observe,
    store,
)


@contextmanager
def serve_bytes_once(payload: bytes, piece: int, pause_s: float = 0.0) -> Iterator[int]:
    """A real TCP server on 127.0.0.1 (its port yielded) that sends ``payload`` to its first client in
    ``piece``-byte pieces (``pause_s`` apart), then closes the connection; closed and joined on exit."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)

    def serve() -> None:
        conn, _ = srv.accept()
        for i in range(0, len(payload), piece):
            conn.sendall(payload[i:i + piece])
            if pause_s:
                time.sleep(pause_s)
        conn.close()

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    try:
        yield srv.getsockname()[1]
    finally:
        srv.close()
        th.join(timeout=5.0)
