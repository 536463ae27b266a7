"""Child-process supervision: the children never outlive the run.

All children share one new process group (so a terminal's Ctrl-C reaches only the launcher,
which then stops them in order), and each asks the kernel to SIGTERM it if the launcher dies
(``PR_SET_PDEATHSIG``), so even a ``kill -9`` of the launcher leaves nothing behind. Stopping
is SIGTERM to the group, a grace period, then SIGKILL.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:  # runs in the child between fork and exec
    with contextlib.suppress(OSError):
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


def free_udp_ports(count: int, host: str = "127.0.0.1") -> list[int]:
    """``count`` distinct UDP ports that were free a moment ago (bound together, then released)."""
    socks = []
    try:
        for _ in range(count):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind((host, 0))
            socks.append(s)
        return [int(s.getsockname()[1]) for s in socks]
    finally:
        for s in socks:
            s.close()


@dataclass(frozen=True, slots=True)
class ChildSpec:
    """One child: a name (used in messages and log file names) and its ``python -m`` argv."""

    name: str
    module_argv: tuple[str, ...]  # e.g. ("simvehicle", "--seed", "1")


@dataclass(frozen=True, slots=True)
class ChildExit:
    name: str
    returncode: int | None  # None: still running when stopped


class Supervisor:
    """Start children in one process group; ``stop`` always ends every one of them."""

    def __init__(self, log_dir: Path, grace_s: float = 3.0) -> None:
        self.log_dir = log_dir
        self.grace_s = grace_s
        self.children: dict[str, subprocess.Popen[bytes]] = {}
        self._pgid: int | None = None
        self._logs: list[object] = []

    def start(self, spec: ChildSpec, stdout: int | None = None) -> subprocess.Popen[bytes]:
        """Start ``python -m <module_argv>``; stderr goes to ``<log_dir>/<name>.log``."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        log = open(self.log_dir / f"{spec.name}.log", "wb")  # noqa: SIM115 (closed in stop)
        self._logs.append(log)
        proc = subprocess.Popen(
            [sys.executable, "-m", *spec.module_argv],
            stdin=subprocess.DEVNULL,
            stdout=stdout if stdout is not None else log,
            stderr=log,
            process_group=0 if self._pgid is None else self._pgid,
            preexec_fn=_die_with_parent,
        )
        if self._pgid is None:
            self._pgid = proc.pid
        self.children[spec.name] = proc
        return proc

    def first_exit(self) -> ChildExit | None:
        """The first child found to have exited, if any (non-blocking)."""
        for name, proc in self.children.items():
            rc = proc.poll()
            if rc is not None:
                return ChildExit(name, rc)
        return None

    def stop(self, order: Sequence[str] = ()) -> dict[str, int | None]:
        """SIGTERM the named children first (in order, each given its grace), then the group;
        SIGKILL whatever is left after the grace period. Returns each child's return code."""
        for name in order:
            proc = self.children.get(name)
            if proc is not None and proc.poll() is None:
                proc.terminate()
                _wait(proc, self.grace_s)
        if self._pgid is not None:
            _signal_group(self._pgid, signal.SIGTERM)
            deadline = time.monotonic() + self.grace_s
            for proc in self.children.values():
                _wait(proc, max(deadline - time.monotonic(), 0.0))
            _signal_group(self._pgid, signal.SIGKILL)
        codes: dict[str, int | None] = {}
        for name, proc in self.children.items():
            if proc.poll() is None:
                proc.kill()
            codes[name] = proc.wait()
        for log in self._logs:
            log.close()  # type: ignore[attr-defined]
        self._logs.clear()
        return codes

    def __enter__(self) -> Supervisor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _wait(proc: subprocess.Popen[bytes], timeout_s: float) -> None:
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=timeout_s)


def _signal_group(pgid: int, sig: signal.Signals) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, sig)


def read_tail(path: Path, max_lines: int = 5) -> str:
    """The last lines of a child's log (to name the cause of a crash in one message)."""
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").strip().splitlines()
    except OSError:
        return ""
    return " | ".join(lines[-max_lines:])


__all__ = ["ChildExit", "ChildSpec", "Supervisor", "free_udp_ports", "read_tail"]
