"""A receiver's decoded items (raw epochs, ephemerides, its own fix) read on a thread, handed over in
arrival order: the companion's main loop drains them between MAVLink messages.

``RawReceiver(url)`` opens the stream at once (a bad URL is a one-line ``UserError``), reads it on a
daemon thread with ``ubx_items`` and queues what it decodes; ``drain()`` returns what arrived since
the last call; ``counters()`` are the decoder's (bad frames, signals not taken, ...) plus ``items``,
``disconnects``, ``reconnects``, ``reconnect_failures``, ``reader_errors_<Exception>`` and
``stream_ended``; ``close()`` stops it.

A companion owns its receiver: when a TCP or serial stream ends (the peer closed, the cable pulled, an
error) the reader says so in one line and reopens it, waiting 0.1 s, then twice as long after each
attempt up to ``MAX_BACKOFF_S`` (back to 0.1 s once a connection has given an item), for as long as
the companion runs; the decoder (its ephemeris halves, the last epoch's time) carries over. A file
read to its end ends (``stream_ended``).
"""

from __future__ import annotations

import contextlib
import queue
import sys
import threading
import time
from collections import Counter
from typing import Any

from companion.errors import UserError
from companion.gnss.ubx import UbxDecoder, UbxItem
from companion.receiver.ubx_stream import open_stream, ubx_items

MAX_QUEUED = 10_000  # items kept while the main loop is busy (10 min of 10 Hz epochs + ephemerides)
MAX_BACKOFF_S = 5.0  # the longest wait between two attempts to reopen a lost receiver


class RawReceiver:
    def __init__(self, url: str, timeout_s: float = 1.0, first_backoff_s: float = 0.1) -> None:
        self.url = url
        self.timeout_s = timeout_s
        self.first_backoff_s = first_backoff_s
        self.live = url.startswith(("tcp:", "serial:"))
        self.stream: Any = open_stream(url, timeout_s)
        self.decoder = UbxDecoder()
        self._queue: queue.Queue[UbxItem] = queue.Queue(MAX_QUEUED)
        self._stop = threading.Event()
        self._counts: Counter[str] = Counter()
        self._thread = threading.Thread(target=self._run, name="ubx-receiver", daemon=True)
        self._thread.start()

    def _read(self) -> str:
        """Read the open stream to its end; why it ended."""
        try:
            clock = time.monotonic if self.live else None
            for item in ubx_items(self.stream, self.decoder, self._stop.is_set, final=False, clock=clock):
                try:
                    self._queue.put_nowait(item)
                    self._counts["items"] += 1
                except queue.Full:
                    self._counts["items_dropped_queue_full"] += 1
        except Exception as exc:  # noqa: BLE001 - the stream failed under us (or a bug): counted, reopened
            self._counts[f"reader_errors_{type(exc).__name__}"] += 1
            return f"{type(exc).__name__}: {exc}"
        finally:
            with contextlib.suppress(OSError):
                self.stream.close()
        return getattr(self.stream, "ended", "") or "the stream ended"

    def _run(self) -> None:
        wait_s = self.first_backoff_s
        while True:
            items_before = self._counts["items"]
            why = self._read()
            if self._stop.is_set() or not self.live:
                break
            self._counts["disconnects"] += 1
            print(f"companion: receiver {self.url}: {why}; reconnecting", file=sys.stderr)
            # a connection that gave nothing (a receiver accepting and dropping) does not reset the wait
            wait_s = self.first_backoff_s if self._counts["items"] > items_before else wait_s
            reopened, wait_s = self._reopen(wait_s)
            if not reopened:
                break
        self._counts["stream_ended"] += 1

    def _reopen(self, wait_s: float) -> tuple[bool, float]:
        """Reopen the stream, waiting ``wait_s`` first and twice as long after each failure; whether it
        reopened (not when closed meanwhile) and the next wait."""
        while not self._stop.wait(wait_s):
            wait_s = min(2.0 * wait_s, MAX_BACKOFF_S)
            try:
                self.stream = open_stream(self.url, self.timeout_s)
            except UserError:
                self._counts["reconnect_failures"] += 1
                continue
            self._counts["reconnects"] += 1
            print(f"companion: receiver {self.url}: reconnected", file=sys.stderr)
            return True, wait_s
        return False, wait_s

    def drain(self) -> list[UbxItem]:
        out: list[UbxItem] = []
        while True:
            try:
                out.append(self._queue.get_nowait())
            except queue.Empty:
                return out

    def counters(self) -> dict[str, Any]:
        return {**dict(self.decoder.counters), **dict(self._counts)}

    def close(self) -> None:
        self._stop.set()
        with contextlib.suppress(OSError):
            self.stream.close()
        self._thread.join(timeout=2.0)
