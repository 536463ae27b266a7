"""Hostile input on the ``--master`` path beside REAL autopilots: PX4 SITL over UDP, ArduCopter SITL
over TCP (through a man in the middle injecting into the stream), signing off and on.

Attacks: a forged autopilot HEARTBEAT (another system, first), the autopilot's own HEARTBEAT with
another type, forged GNSS 5,000 km away, lone stamps an hour ahead, bursts 2 s ahead, stamps 8 s
back, junk floods (random bytes, false magic bytes, cut frames, bad CRCs, unknown ids) from
hundreds of source addresses, a SYSTEM_TIME of 2^63, an unsolicited PARAM_VALUE; with signing on,
all of it unsigned. Every run ends with checks that the real autopilot was found and kept, every
forgery was refused where it should be (counted), no genuine frame was lost (TCP: exactly), the
estimate still agrees with the autopilot's own, and the run ended truthfully (a SIGKILL leaves a
summary.json of the last second; a dead autopilot is exit 1 and one line).

One PX4 and one ArduPilot per module (module-scoped fixtures); the whole file ~50 s.
"""

from __future__ import annotations

import json
import signal
import time

import numpy as np
import pytest
from ardupilot_helpers import require_ardupilot, run_companion, stop
from autopilot_stream import gps, heartbeat, imu, system_time
from master_attack import InjectingProxy, UdpAttacker, frame, junk, wait_for
from px4_helpers import px4_fixture
from pymavlink.dialects.v20 import common as mavlink

from companion.autopilot.node import CompanionConfig
from companion.autopilot.service import run as run_companion_in_process
from companion.autopilot.signing_setup import setup_signing
from companion.errors import UserError
from companion.mavlink.signing import Signer

KEY = bytes(range(100, 132))
SEED = 26
FAR_LAT_DEG = -45.0  # added to the home latitude: 5,000 km away
px4 = px4_fixture(speed_factor=5.0)


def _summary(out) -> dict:
    return json.loads((out / "summary.json").read_text())


def _discovered(out) -> dict | None:
    """The summary once the autopilot is found and the frame placed (rewritten every second)."""
    try:
        s = _summary(out)
    except (OSError, ValueError):
        return None
    return s if s.get("autopilot") and s["clock"]["base_us"] and s["home"] else None


def _fresh(out) -> dict:
    """A summary written from now on: its clock base is the autopilot's boot time of this moment."""
    since = time.time()
    wait_for(lambda: (out / "summary.json").stat().st_mtime > since, 5.0, 0.02)
    return _summary(out)


def _forgeries(system_id: int, base_us: int, home: dict, seq0: int) -> list[tuple[bytes, str]]:
    """The autopilot's ids on frames that must all be refused by the node (see the module doc)."""
    f = [(frame(imu(base_us + 3_600_000_000), system_id, seq=seq0), "imu_hour_ahead")]
    burst = [frame(imu(base_us + 2_000_000 + k * 20_000, acc_y=5.0), system_id, seq=seq0 + 1 + k)
             for k in range(10)]
    f.append((b"".join(burst), "imu_burst_2s_ahead"))
    for k in range(3):
        back = imu(max(base_us - 8_000_000, 0) + k * 20_000)
        f.append((frame(back, system_id, seq=seq0 + 20 + k), "imu_8s_back"))
    far = gps(base_us, lat=home["lat_deg"] + FAR_LAT_DEG, lon=home["lon_deg"], alt=home["alt_m"])
    f.append((frame(far, system_id, seq=seq0 + 30), "gnss_5000_km"))
    f.append((frame(system_time(base_us, unix_us=2**63 - 1), system_id, seq=seq0 + 31), "system_time_2_63"))
    for k, (name, value) in enumerate(((b"EKF2_GPS_DELAY", 1000.0), (b"GPS1_DELAY_MS", 250.0))):
        param = mavlink.MAVLink_param_value_message(name, value, 9, 1000, 65535)
        f.append((frame(param, system_id, seq=seq0 + 32 + k), "param_value_unsolicited"))
    hexa = heartbeat(mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, mavlink.MAV_TYPE_HEXAROTOR)
    f.append((frame(hexa, system_id, seq=seq0 + 34), "heartbeat_other_type"))
    return f


def _check_forgeries_refused(s: dict) -> None:
    node, rejected = s["node"], s["samples"]["rejected"]
    assert node.get("rejected_clock_highres_imu", 0) >= 1 + 10 + 3, node
    assert node.get("autopilot_reboots", 0) == 0
    assert s["estimator_counters"].get("imu_rejected_time_backwards", 0) == 0  # the genuine stream unharmed
    assert rejected.get("rejected_gnss_far_from_home") == 1
    assert rejected.get("rejected_system_time_range") == 1
    assert rejected.get("param_value_unsolicited", 0) >= 2
    assert rejected.get("autopilot_inconsistent_heartbeat", 0) >= 1
    assert not [k for k in rejected if k.startswith(("handler_error", "unsendable"))], rejected
    err = s["errors"]["autopilot_estimate"]
    horizontal = err["error_horizontal_m"]
    assert horizontal["count"] > 50 and horizontal["median"] < 1.0  # still with the autopilot's EKF


def _hostile_heartbeats(attacker: UdpAttacker, seconds: float) -> None:
    hb = heartbeat()  # a PX4 quadrotor
    end = time.monotonic() + seconds
    k = 0
    while time.monotonic() < end:
        attacker.send(frame(hb, 42, seq=k), "heartbeat_system_42")
        k += 1
        time.sleep(0.1)


def test_px4_over_udp_survives_spoofing_floods_and_forged_stamps(px4, tmp_path):
    rng = np.random.default_rng(SEED)
    out = tmp_path / "companion"
    attacker = UdpAttacker(px4.offboard_port, addresses=300)
    proc = run_companion(px4.url, out, "--duration-s", "60")
    try:
        _hostile_heartbeats(attacker, 2.0)  # system 42 claims to be the autopilot from the start
        wait_for(lambda: _discovered(out), 20.0)
        s = _fresh(out)
        for data, kind in _forgeries(px4.system_id, s["clock"]["base_us"] + 200_000, s["home"], 0):
            attacker.send(data, kind)
        sample = frame(heartbeat(), px4.system_id)
        t0 = time.monotonic()
        for _ in range(3000):  # a junk flood from 300 addresses
            attacker.send(junk(rng, sample), "junk")
        flood_wall_s = time.monotonic() - t0
        _hostile_heartbeats(attacker, 0.5)
        time.sleep(3.0)
        killed_at = time.monotonic()
        proc.send_signal(signal.SIGKILL)  # no exit handler runs: the summary of the last second
        proc.wait(timeout=10)
    finally:
        attacker.close()
        stop(proc)
    s = _summary(out)
    assert s["wall_s"] > killed_at - t0 - 2.0 and s["failure"] is None
    ap = s["autopilot"]
    assert (ap["system_id"], ap["component_id"], ap["autopilot_type"]) == (px4.system_id, 1, 12)
    conflicting = [p for p in s["problems"] if "second autopilot (system 42" in p or "system 42 (" in p]
    assert len(conflicting) == 1, s["problems"]
    rejected = s["samples"]["rejected"]
    assert rejected["autopilot_conflicting_autopilot"] >= 3 and s["conflicting_autopilots"] == [42]
    # system 42's HEARTBEATs are the only other system: PX4's own unknown message ids are not
    assert rejected["autopilot_other_system"] == rejected["autopilot_conflicting_autopilot"]
    assert s["link"]["unknown_message"] > 0
    _check_forgeries_refused(s)
    link = s["link"]
    assert link["garbage"] + link.get("bad_crc", 0) + link.get("unknown_message", 0) >= 3000 - 10
    assert link.get("peers_added", 0) <= 4  # PX4 and forgers, bounded (300 addresses sent)
    received = s["samples"]["received"]
    assert received["HIGHRES_IMU"] > 0.9 * s["samples"]["used"]["imu"] > 500
    assert flood_wall_s < 5.0


def test_px4_has_no_signing_a_signed_companion_refuses_it_and_setup_signing_says_so(px4, tmp_path):
    """This PX4 (main between v1.15 and v1.16) ignores SETUP_SIGNING and never signs: a companion
    with a key refuses all of its frames (counted) and says why in one line."""
    ok, line = setup_signing(px4.url, KEY, discovery_timeout_s=15.0, confirm_s=2.0)
    assert not ok and f"system {px4.system_id} (MAV_AUTOPILOT_PX4) does not sign" in line
    out = tmp_path / "signed"
    why = r"no autopilot HEARTBEAT within 2 s \(\d+ frames refused: not signed"
    with pytest.raises(UserError, match=why):
        run_companion_in_process(CompanionConfig(master=px4.url, out_dir=out, signing_key=KEY,
                                                 discovery_timeout_s=2.0))
    s = _summary(out)
    assert s["autopilot"] is None and s["link"]["unsigned"] > 100 and s["link"].get("received", 0) == 0
    assert s["security"]["signing"] is True


def test_px4_that_dies_is_a_lost_autopilot_exit_1_and_one_line(px4, tmp_path):
    """(Last in the module: it stops the module's PX4.)"""
    out = tmp_path / "companion"
    proc = run_companion(px4.url, out, "--lost-timeout-s", "3.5", "--duration-s", "60")
    try:
        wait_for(lambda: _discovered(out), 20.0)
        px4.stop()
        proc.wait(timeout=20)
    finally:
        code, err = stop(proc)
    lines = err.strip().splitlines()
    assert code == 1 and lines[-1].startswith("beliefnav: error: the autopilot (system"), err
    assert lines[-1].endswith(": lost") and "silent for" in lines[-1]
    s = _summary(out)
    assert s["failure"] == lines[-1].removeprefix("beliefnav: error: ") and s["failure"] in s["problems"]


# --- ArduCopter over TCP, through a man in the middle ------------------------------------------
@pytest.fixture(scope="module")
def arducopter(tmp_path_factory):
    require_ardupilot()
    from simvehicle.harness.ardupilot.sitl import ArduPilotSitl, SitlConfig

    with ArduPilotSitl(SitlConfig(work_dir=tmp_path_factory.mktemp("ardupilot"), speedup=10)) as sitl:
        yield sitl


def _through_proxy(sitl, out, rng, seconds: float, forged: bool, *extra: str) -> tuple[dict, InjectingProxy]:
    """The companion on SERIAL0 through an injecting proxy for ``seconds`` after discovery: junk
    between every few frames, forged frames (unsigned) if ``forged``; then the stream is paused,
    the companion drains it and stops. Returns its summary and the proxy (its counts)."""
    proxy = InjectingProxy(("127.0.0.1", sitl.ports[0]))
    proc = run_companion(proxy.url, out, "--duration-s", "60", *extra)
    sample = frame(heartbeat(mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA), 1)
    hb42 = heartbeat()
    try:
        for k in range(10):  # system 42 claims to be the autopilot before ArduPilot's first HEARTBEAT
            proxy.inject(frame(hb42, 42, seq=k), frames=1)
            time.sleep(0.05)
        wait_for(lambda: _discovered(out), 25.0)
        if forged:
            s = _fresh(out)
            for data, kind in _forgeries(1, s["clock"]["base_us"] + 200_000, s["home"], 100):
                proxy.inject(data, frames=10 if kind == "imu_burst_2s_ahead" else 1)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for _ in range(20):
                proxy.inject(junk(rng, sample))
            time.sleep(0.02)
        wait_for(lambda: proxy.pending() == 0, 5.0)
        proxy.paused.set()
        time.sleep(1.0)  # everything forwarded is read
    finally:
        code, err = stop(proc)
        proxy.close()
    assert code in (0, 143), err  # 143: stopped by SIGTERM, the summary written
    return _summary(out), proxy


def _check_tcp_accounting(s: dict, proxy: InjectingProxy) -> None:
    """No genuine frame lost in the junk: every frame forwarded (and every valid one injected) was
    received by the link, exactly."""
    genuine = sum(n for kind, n in proxy.forwarded.items() if not kind.startswith("UNKNOWN"))
    link = s["link"]
    accepted_or_refused = link.get("received", 0) + link.get("unsigned", 0) + link.get("bad_signature", 0)
    assert accepted_or_refused == genuine + proxy.injected_frames, (link, genuine, proxy.injected_frames)
    damaged = link["garbage"] + link.get("bad_crc", 0) + link.get("unknown_message", 0)  # per damaged span
    assert proxy.injected_junk > 500 and damaged >= 20


def test_arducopter_over_tcp_junk_in_the_stream_loses_no_frame_and_forgeries_are_refused(arducopter,
                                                                                       tmp_path):
    rng = np.random.default_rng(SEED + 1)
    s, proxy = _through_proxy(arducopter, tmp_path / "companion", rng, 4.0, forged=True)
    _check_tcp_accounting(s, proxy)
    ap = s["autopilot"]
    assert (ap["system_id"], ap["autopilot_type"]) == (1, 3)
    assert any("system 42" in p for p in s["problems"])
    _check_forgeries_refused(s)


def test_arducopter_signing_setup_then_unsigned_forgeries_are_refused_at_the_link(arducopter, tmp_path):
    """SETUP_SIGNING on SERIAL0 (ArduPilot's "USB" port): it signs everything from then on, on every
    port, and refuses unsigned frames except on SERIAL0. With the key, the companion refuses every
    unsigned frame in the stream: no forgery reaches the node."""
    ok, line = setup_signing(arducopter.url, KEY, discovery_timeout_s=15.0, confirm_s=3.0)
    assert ok, line
    key_file = tmp_path / "signing.key"
    key_file.write_text(KEY.hex())
    rng = np.random.default_rng(SEED + 2)
    s, proxy = _through_proxy(arducopter, tmp_path / "companion", rng, 3.0, True,
                              "--signing-key-file", str(key_file))
    _check_tcp_accounting(s, proxy)
    assert s["security"] == {"signing": True, "loopback": True, "warning": None}
    assert s["autopilot"]["system_id"] == 1 and not any("system 42" in p for p in s["problems"])
    assert s["link"]["unsigned"] >= proxy.injected_frames  # every forgery, at the link
    assert not [k for k in s["node"] if k.startswith("rejected_clock")], s["node"]
    assert s["samples"]["used"]["imu"] > 100
    assert s["errors"]["autopilot_estimate"]["error_horizontal_m"]["median"] < 1.0

    serial1 = arducopter.wait_serial(1)  # another port: unsigned commands are refused, signed ones not
    import socket

    host, port = serial1.split(":")[1:]
    with socket.create_connection((host, int(port))) as sock:
        signer = Signer(KEY, link_id=7)
        ask = mavlink.MAVLink_command_long_message(1, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                                   mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
        before = signer.timestamp
        assert _acks(sock, signer, frame(ask, 1, 196)) == 0
        # ArduPilot SITL's signing clock is its simulated GPS time (x10 here): ahead of ours. The
        # signer takes the newest timestamp it verified (as MAVLink's C library does), else
        # ArduPilot refuses our frames as replays
        assert signer.timestamp > before
        assert _acks(sock, signer, frame(ask, 1, 196, seq=1, signer=signer), enough=1) >= 1


def _acks(sock, signer: Signer, data: bytes, wait_s: float = 1.5, enough: int | None = None) -> int:
    """COMMAND_ACKs to ``data`` within ``wait_s`` (the frames read verified by ``signer``); as soon as
    there are ``enough`` of them, if given."""
    from companion.mavlink.frames import StreamScanner

    sock.sendall(data)
    scanner, n = StreamScanner("ardupilotmega"), 0
    sock.settimeout(0.1)
    end = time.monotonic() + wait_s
    while time.monotonic() < end and (enough is None or n < enough):
        try:
            chunk = sock.recv(65536)
        except TimeoutError:
            continue
        for v in scanner.feed(chunk)[0]:
            assert signer.check(v.get_msgbuf(), v.get_srcSystem(), v.get_srcComponent())  # all signed
            n += v.get_type() == "COMMAND_ACK" and v.command == mavlink.MAV_CMD_REQUEST_MESSAGE
    return n
