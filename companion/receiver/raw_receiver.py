"""A receiver's decoded items (raw epochs, ephemerides, its own fix) read on a thread, handed over in
arrival order: the companion's main loop drains them between MAVLink messages.

``RawReceiver(url)`` opens the stream at once (a bad URL is a one-line ``UserError``), reads it on a
daemon thread with ``ubx_items`` and queues what it decodes; ``drain()`` returns what arrived since
the last call; ``counters()`` are the decoder's (bad frames, signals not taken, ...) plus ``items``
and ``stream_ended``; ``close()`` stops it.
"""

from __future__ import annotations

import contextlib
import queue
import threading
from collections import Counter
from typing import Any

from companion.gnss.ubx import UbxDecoder, UbxItem
from companion.receiver.ubx_stream import open_stream, ubx_items

MAX_QUEUED = 10_000  # items kept while the main loop is busy (10 min of 10 Hz epochs + ephemerides)


class RawReceiver:
    def __init__(self, url: str, timeout_s: float = 1.0) -> None:
        self.url = url
        self.stream = open_stream(url, timeout_s)
        self.decoder = UbxDecoder()
        self._queue: queue.Queue[UbxItem] = queue.Queue(MAX_QUEUED)
        self._stop = threading.Event()
        self._counts: Counter[str] = Counter()
        self._thread = threading.Thread(target=self._run, name="ubx-receiver", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            for item in ubx_items(self.stream, self.decoder):
                if self._stop.is_set():
                    return
                try:
                    self._queue.put_nowait(item)
                    self._counts["items"] += 1
                except queue.Full:
                    self._counts["items_dropped_queue_full"] += 1
        except (OSError, ValueError):  # the stream closed under us
            self._counts["stream_errors"] += 1
        self._counts["stream_ended"] += 1

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
