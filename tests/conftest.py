"""Test-run isolation: every Zenoh session of this run (and of the processes it starts) uses a
private hub port, so concurrent runs and a developer's live tools never share a mesh."""

import os
import socket


def pytest_configure(config):
    if "BELIEFNAV_ZENOH_HUB" not in os.environ:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            os.environ["BELIEFNAV_ZENOH_HUB"] = f"tcp/127.0.0.1:{s.getsockname()[1]}"
