"""Process plumbing shared by the vehicle and companion processes (no numerics here)."""

from __future__ import annotations

import json
import os
import signal
import sys
from pathlib import Path
from types import FrameType
from typing import Any


def exit_on_sigterm() -> None:
    """Turn SIGTERM into ``SystemExit`` so ``finally`` blocks flush logs and statistics."""

    def _handler(signum: int, frame: FrameType | None) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a second SIGTERM ends us at once
        sys.exit(128 + signum)

    signal.signal(signal.SIGTERM, _handler)


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
