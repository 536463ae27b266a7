"""The simulated receiver's UBX byte stream on a TCP port (127.0.0.1), like a receiver behind a
serial-to-TCP bridge: ``gcs_tools.gnss.ubx_source.open_stream("tcp:127.0.0.1:PORT")`` and any
u-blox tool (u-center, pyubx2, RTKLIB ``tcpcli://``) read it.

Never blocks the vehicle: connections are accepted and written without waiting; a client that
reads too slowly (more than ``MAX_BACKLOG_BYTES`` pending) is dropped and counted. Every frame
also goes to a log file (``receiver.ubx``), which ``beliefnav gnss spp`` reads.
"""

from __future__ import annotations

import errno
import math
import socket
from dataclasses import asdict
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from companion.errors import UserError
from companion.gnss.ephemeris import EphemerisStore, GlonassEphemeris, KeplerEphemeris
from companion.runtime import write_json
from simvehicle.rawgnss import RawGnssModel
from simvehicle.receiver import RawObservation
from simvehicle.ubx import UbxEncoder

MAX_BACKLOG_BYTES = 4 << 20


class UbxServer:
    def __init__(self, port: int = 0, log_path: Path | None = None, host: str = "127.0.0.1") -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            raise UserError(f"UBX TCP port {port} on {host}: {exc.strerror or exc}") from None
        self._sock.listen(4)
        self._sock.setblocking(False)
        self.host = host
        self.port = int(self._sock.getsockname()[1])
        self._clients: list[tuple[socket.socket, bytearray]] = []
        self._log: BinaryIO | None = open(log_path, "wb") if log_path is not None else None  # noqa: SIM115
        self.counters: dict[str, int] = {
            "frames": 0,
            "bytes": 0,
            "clients": 0,
            "dropped_slow": 0,
            "dropped_closed": 0,
        }

    @property
    def url(self) -> str:
        return f"tcp:{self.host}:{self.port}"

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self._sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._clients.append((conn, bytearray()))
            self.counters["clients"] += 1

    def send(self, frames: list[bytes]) -> None:
        """Queue ``frames`` to every client and write what each socket takes now."""
        self._accept()
        if not frames:
            self._flush()
            return
        data = b"".join(frames)
        self.counters["frames"] += len(frames)
        self.counters["bytes"] += len(data)
        if self._log is not None:
            self._log.write(data)
        for _, pending in self._clients:
            pending += data
        self._flush()

    def _flush(self) -> None:
        keep = []
        for conn, pending in self._clients:
            try:
                while pending:
                    n = conn.send(pending)
                    del pending[:n]
            except BlockingIOError:
                pass
            except OSError as exc:
                conn.close()
                self.counters[
                    "dropped_closed" if exc.errno in (errno.EPIPE, errno.ECONNRESET) else "dropped_slow"
                ] += 1
                continue
            if len(pending) > MAX_BACKLOG_BYTES:
                conn.close()
                self.counters["dropped_slow"] += 1
                continue
            keep.append((conn, pending))
        self._clients = keep

    def close(self) -> None:
        self._flush()
        for conn, _ in self._clients:
            conn.close()
        self._clients = []
        self._sock.close()
        if self._log is not None:
            self._log.close()
            self._log = None


class ReceiverStream:
    """A vehicle process's raw receiver outputs: UBX frames (:mod:`simvehicle.ubx`) on the TCP port and
    in ``receiver.ubx``, and ``receiver.json`` (the port, the GPS time of boot, the broadcast
    ephemerides as ``EphemerisStore`` fields: the same ephemerides the stream's RXM-SFRBX carries, for a
    consumer that does not decode navigation messages), rewritten when the ephemerides are extended."""

    def __init__(self, gnss: RawGnssModel, port: int, out_dir: Path) -> None:
        self.gnss = gnss
        self.out_dir = out_dir
        self.server = UbxServer(port, out_dir / "receiver.ubx")
        self.encoder = UbxEncoder(gnss.store)
        self._write_info()

    def _write_info(self) -> None:
        store = self.gnss.store
        write_json(
            self.out_dir / "receiver.json",
            {
                "ubx": self.server.url,
                "log": "receiver.ubx",
                "t0_gps_s": self.gnss.t0_gps_s,
                "boot_time": "GPS time = t0_gps_s + boot time (s); RXM-RAWX rcvTow adds the receiver "
                "clock offset",
                "systems": list(self.gnss.cfg.systems),
                "rate_hz": self.gnss.cfg.rate_hz,
                "ephemerides": {
                    "kepler": [_kepler_json(e) for e in store.kepler],
                    "glonass": [asdict(g) for g in store.glonass],
                    "klobuchar": None
                    if store.klobuchar is None
                    else [list(map(float, v)) for v in store.klobuchar],
                },
            },
        )

    def send(self, raws: list[RawObservation]) -> None:
        if self.gnss.store is not self.encoder.store:
            self.encoder.store = self.gnss.store
            self._write_info()
        self.server.send([f for raw in raws for f in self.encoder.epoch_frames(raw)])

    def close(self) -> None:
        self.server.close()


def _kepler_json(e: KeplerEphemeris) -> dict[str, Any]:
    """A Keplerian ephemeris as strict JSON: an accuracy not given (NaN) as null, "no prediction"
    (inf) as the string "inf"."""
    d = asdict(e)
    acc = d["accuracy_m"]
    d["accuracy_m"] = None if math.isnan(acc) else "inf" if math.isinf(acc) else acc
    return d


def _accuracy(value: float | str | None) -> float:
    """``_kepler_json``'s accuracy back: null -> NaN (not given), "inf" -> inf, a number as itself."""
    return math.nan if value is None else float(value)


def store_from_info(info: dict[str, Any]) -> EphemerisStore:
    """The ``EphemerisStore`` of a ``receiver.json``'s ``ephemerides`` (its consumer's side)."""
    eph = info["ephemerides"]
    klob = eph.get("klobuchar")
    glonass = []
    for g in eph["glonass"]:
        fields: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in g.items()}
        glonass.append(GlonassEphemeris(**fields))
    return EphemerisStore(
        [KeplerEphemeris(**{**e, "accuracy_m": _accuracy(e.get("accuracy_m"))}) for e in eph["kepler"]],
        glonass,
        None if klob is None else (np.array(klob[0]), np.array(klob[1])),
    )
