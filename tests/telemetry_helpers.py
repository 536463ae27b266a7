"""Shared fixtures for the telemetry tests: a private Zenoh hub port and child processes that die."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def hub_env() -> dict[str, str]:
    """Environment with a private hub port, so concurrent test runs never share a mesh."""
    return {**os.environ, "BELIEFNAV_ZENOH_HUB": f"tcp/127.0.0.1:{free_port()}"}


@contextmanager
def child(args: list[str], env: dict[str, str], **kw) -> Iterator[subprocess.Popen]:
    """A Python child process (``-m`` module or ``-c``), always killed on exit."""
    proc = subprocess.Popen([sys.executable, *args], env=env, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, **kw)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=10)
