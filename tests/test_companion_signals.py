"""Ctrl-C and SIGTERM end the companion between messages, not at whatever line runs when the signal
lands: the run ends whole (summary.json says which signal, the tlog's frames are whole) however busy
the link is, and a second signal ends it at once."""

from __future__ import annotations

import json
import os
import signal
import socket
import threading
import time

import pytest
from ardupilot_helpers import run_companion, stop
from pymavlink import mavutil
from test_autopilot_udp import _frames, _free_udp_port

from companion.runtime import stop_on_signals


def _wait_for(request, seconds: float = 5.0) -> None:
    """A signal sent to ourselves is handled at the interpreter's next check: wait for it."""
    deadline = time.monotonic() + seconds
    while not request and time.monotonic() < deadline:
        time.sleep(0.001)


def test_first_signal_is_a_request_the_second_ends_at_once_handlers_restored():
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    with stop_on_signals() as request:
        assert not request and request.name is None
        os.kill(os.getpid(), signal.SIGTERM)
        _wait_for(request)
        assert request and request.name == "SIGTERM"
        with pytest.raises(KeyboardInterrupt):  # the second; the first (SIGTERM) stays the one recorded
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)
        assert request.name == "SIGTERM"
    assert {s: signal.getsignal(s) for s in before} == before
    with stop_on_signals() as request:
        os.kill(os.getpid(), signal.SIGINT)
        _wait_for(request)
        assert request.name == "SIGINT"
        with pytest.raises(SystemExit) as ended:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5.0)
        assert ended.value.code == 128 + signal.SIGTERM
    assert {s: signal.getsignal(s) for s in before} == before


def test_an_ignored_sigint_still_stops_the_run_and_is_ignored_again_after():
    """A script's background job starts with SIGINT ignored (Python keeps SIG_IGN): a run must still
    stop on it (this is how a companion once ran on for 30 s after a test's Ctrl-C)."""
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with stop_on_signals() as request:
            os.kill(os.getpid(), signal.SIGINT)
            _wait_for(request)
            assert request.name == "SIGINT"
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, before)


def test_outside_the_main_thread_nothing_is_installed():
    seen = {}

    def other() -> None:
        with stop_on_signals() as request:
            seen["handler"] = signal.getsignal(signal.SIGINT)
            seen["request"] = bool(request)

    before = signal.getsignal(signal.SIGINT)
    t = threading.Thread(target=other)
    t.start()
    t.join()
    assert seen == {"handler": before, "request": False}


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 0), (signal.SIGTERM, 128 + signal.SIGTERM)])
def test_companion_busy_on_a_stream_ends_whole_on_a_signal(tmp_path, signum, code):
    """A real flight log streamed over UDP at 10x; the signal lands mid-stream, the process runs for
    10 minutes otherwise. It ends cleanly (exit 0 after Ctrl-C, 143 after SIGTERM, as a service manager
    expects), its summary names the signal and holds the samples it used, and pymavlink reads its tlog
    to the last frame without a broken one. A SIGUSR1 before prints its stack and it goes on."""
    frames = _frames(8.0)
    port = _free_udp_port()
    out = tmp_path / "companion"
    proc = run_companion(f"udpin:127.0.0.1:{port}", out, "--duration-s", "600")
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        heartbeat = next(f for _, kind, f in frames if kind == "HEARTBEAT")
        deadline = time.monotonic() + 60
        while not (out / "summary.json").exists():  # written once the loop runs
            assert time.monotonic() < deadline and proc.poll() is None
            sock.sendto(heartbeat, ("127.0.0.1", port))
            time.sleep(0.2)
        start = time.monotonic()
        for i, (t_s, _, frame) in enumerate(frames):
            delay = t_s / 10.0 - (time.monotonic() - start)
            if delay > 0:
                time.sleep(delay)
            sock.sendto(frame, ("127.0.0.1", port))
            if i == len(frames) // 4:
                proc.send_signal(signal.SIGUSR1)  # where is it? (it goes on)
            if i == len(frames) // 2:
                proc.send_signal(signum)
        proc.wait(timeout=60)
    finally:
        sock.close()
        returncode, err = stop(proc)
    assert returncode == code, err
    assert "in serve" in err and "companion/autopilot/service.py" in err, err  # faulthandler's dump
    s = json.loads((out / "summary.json").read_text())
    assert s["stop_signal"] == signal.Signals(signum).name and s["failure"] is None
    assert s["autopilot"]["system_id"] == 1 and s["samples"]["used"]["imu"] > 0
    log = mavutil.mavlink_connection(str(out / "run.tlog"), dialect="ardupilotmega")
    kinds = []
    while (msg := log.recv_match()) is not None:
        kinds.append(msg.get_type())
    log.close()
    assert "BAD_DATA" not in kinds and kinds.count("HIGHRES_IMU") > 100  # the log's IMU, every frame whole
