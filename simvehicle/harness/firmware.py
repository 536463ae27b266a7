"""What the real-firmware launchers (ArduCopter SITL, PX4 SITL) share: probing a port, stopping a
firmware's whole process group, and the tail of its log for one-line errors."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
from pathlib import Path


def port_free(port: int, kind: int = socket.SOCK_STREAM) -> bool:
    """Whether ``port`` can be bound on every address (firmware listens on 0.0.0.0: a 127.0.0.1
    bind may succeed while another instance holds 0.0.0.0 with SO_REUSEADDR)."""
    with socket.socket(socket.AF_INET, kind) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def signal_group(proc: subprocess.Popen[bytes], sig: signal.Signals) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, sig)


def stop_group(proc: subprocess.Popen[bytes], timeout_s: float) -> int | None:
    """SIGTERM to ``proc``'s process group, SIGKILL after ``timeout_s``; its exit code."""
    if proc.poll() is None:
        signal_group(proc, signal.SIGTERM)
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            signal_group(proc, signal.SIGKILL)
            proc.wait()
    return proc.returncode


def log_tail(path: Path, lines: int = 3) -> str:
    """The last ``lines`` lines of a firmware's log, joined for a one-line error."""
    try:
        text = path.read_text(errors="replace").strip().splitlines()
    except OSError:
        return "(no output)"
    return " | ".join(text[-lines:]) or "(no output)"
