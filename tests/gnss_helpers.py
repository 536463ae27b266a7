"""The synthetic constellation of ``gcs_tools.gnss.synthetic`` under the names the tests use, a
tightly coupled navigator held at rest under it, and a receiver's byte stream served over TCP."""

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from companion.domain.samples import AttitudeSample, ImuSample
from companion.tight import RawGnss
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


def hold_at_rest(nav: Any, sky: Any, imu_samples: int) -> int:
    """Push ``imu_samples`` level attitude + IMU samples at 50 Hz from t = 1 s, and a raw epoch of
    ``sky`` observed at RX_ECEF every 0.2 s, into ``nav`` (a TightNavigator); returns the epochs pushed."""
    q, f = np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.0, -9.80665])
    epochs = 0
    for k in range(imu_samples):
        t_us = 1_000_000 + 20_000 * k
        nav.push(AttitudeSample(t_us, q))
        nav.push(ImuSample(t_us, f, np.zeros(3)))
        if k % 10 == 0:
            ep, _ = observe(sky, T0 + k * 0.02, RX_ECEF)
            nav.push(RawGnss(t_us, ep))
            epochs += 1
    return epochs


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
