"""Process plumbing shared by the vehicle and companion processes (no numerics here)."""

from __future__ import annotations

import contextlib
import faulthandler
import json
import os
import signal
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from types import FrameType
from typing import Any


def exit_on_sigterm() -> None:
    """Turn SIGTERM into ``SystemExit`` so ``finally`` blocks flush logs and statistics."""

    def _handler(signum: int, frame: FrameType | None) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a second SIGTERM ends us at once
        sys.exit(128 + signum)

    signal.signal(signal.SIGTERM, _handler)


class StopRequest:
    """What :func:`stop_on_signals` hands a run loop: ``signum`` is the first SIGINT or SIGTERM received
    (None until then); the loop reads it between messages and ends where its state is whole."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def __bool__(self) -> bool:
        return self.signum is not None

    @property
    def name(self) -> str | None:
        return None if self.signum is None else signal.Signals(self.signum).name


@contextlib.contextmanager
def stop_on_signals() -> Iterator[StopRequest]:
    """SIGINT (Ctrl-C) and SIGTERM as a request to stop, not an exception: an exception raised at
    whatever line runs when the signal lands can cut a frame in the tlog in half or be lost in a
    finaliser, and a busy run must still end. A second signal ends the process at once, as a signal
    does without this (KeyboardInterrupt for SIGINT, SystemExit 128 + signum for SIGTERM). Installed
    even over an ignored SIGINT: a shell starts a script's background jobs with SIGINT ignored, which
    Python keeps, so ``kill -INT`` (or the script's Ctrl-C) would not end such a run at all. The
    handlers before are restored on leaving. Outside the main thread (where Python cannot install
    handlers) nothing is installed and the request stays empty."""
    request = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield request
        return

    def _handler(signum: int, frame: FrameType | None) -> None:
        if request.signum is None:
            request.signum = signum
        elif signum == signal.SIGINT:
            raise KeyboardInterrupt
        else:
            sys.exit(128 + signum)

    before = {s: signal.signal(s, _handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield request
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)


def dump_stacks_on_sigusr1() -> None:
    """``kill -USR1 PID`` prints every thread's Python stack to stderr (``faulthandler``) and the
    process goes on: where a process that does not end is waiting, without stopping it."""
    stream = sys.__stderr__  # the process's own: a stand-in sys.stderr (a test's capture) has no fd
    if hasattr(signal, "SIGUSR1") and stream is not None:
        with contextlib.suppress(ValueError, OSError):  # no file descriptor behind it
            faulthandler.register(signal.SIGUSR1, file=stream, all_threads=True)


def write_json(path: str | os.PathLike[str], obj: Any) -> None:
    """Write ``obj`` atomically (temporary file, then rename) so readers never see half a file."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(obj, indent=2, sort_keys=True, default=_jsonable) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _jsonable(value: Any) -> Any:
    if hasattr(value, "tolist"):
        return value.tolist()
    if hasattr(value, "item"):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def count_handler_error(counters: dict[str, int], process: str, msg: Any, exc: Exception) -> None:
    """Count a message that made a handler raise (``handler_error_<exception>``); the first of each
    kind is printed to stderr with the process name. A frame must never end a process."""
    name = f"handler_error_{type(exc).__name__}"
    if name not in counters:
        print(f"{process}: {msg.get_type()} raised {type(exc).__name__}: {exc}", file=sys.stderr)
    counters[name] = counters.get(name, 0) + 1
