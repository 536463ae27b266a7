"""``beliefnav companion --master URL --signing-key-file KEY --setup-signing``: give the autopilot our
MAVLink 2 signing key the way its users do (MAVProxy's ``signing setup``, QGroundControl), then
check that it really signs with it.

1. Connect unsigned and elect the autopilot (:mod:`.discovery`; ``--target-system`` pins it).
2. Send SETUP_SIGNING (target, the 32-byte key, initial timestamp = now in 10 µs ticks since
   2015) three times, unsigned: an autopilot without a key takes it in clear. Do it over a link
   you trust (USB, a wire): the key crosses it in clear (a warning says so on any other link).
3. From then on sign what we send and refuse what is not signed with the key; the setup is
   confirmed by ``confirm_heartbeats`` signed HEARTBEATs of the autopilot within ``confirm_s``.

Measured: ArduCopter (4.7-dev SITL) stores the key (it survives a reboot), signs every frame on
every port from then on and, except on SERIAL0 (its "USB" port, always trusted), refuses
unsigned frames. The PX4 build used here (main between v1.15 and v1.16) ignores SETUP_SIGNING:
its frames stay unsigned, so the check fails with that said; PX4 from v1.16 has MAVLink signing
(``MAV_SIGN_CFG``), not tested here.
"""

from __future__ import annotations

import argparse
import math
import time

from pymavlink.dialects.v20 import common as mavlink

from companion.autopilot.connection import open_connection, parse_connection
from companion.autopilot.discovery import Discovery, DiscoveryConfig
from companion.autopilot.options import DEFAULT_COMPONENT_ID
from companion.errors import UserError
from companion.mavlink.signing import Signer, read_signing_key, signing_timestamp_now

SETUP_REPEATS = 3


def setup_signing(master: str, key: bytes, target_system: int | None = None,
                  component_id: int = DEFAULT_COMPONENT_ID, discovery_timeout_s: float = 30.0,
                  confirm_s: float = 5.0, confirm_heartbeats: int = 2) -> tuple[bool, str]:
    """(confirmed, one line saying what happened)."""
    endpoint = parse_connection(master)
    conn = open_connection(master, 1, component_id, None)
    discovery = Discovery(DiscoveryConfig(target_system=target_system))
    try:
        deadline = time.monotonic() + discovery_timeout_s
        while discovery.autopilot is None:
            if time.monotonic() > deadline:
                raise UserError(f"--master {master}: no autopilot HEARTBEAT within {discovery_timeout_s:g} s")
            for msg in conn.recv(0.1):
                discovery.accept(msg, time.monotonic())
        ap = discovery.autopilot
        conn.set_source(ap.system_id, component_id)
        setup = mavlink.MAVLink_setup_signing_message(ap.system_id, ap.component_id, list(key),
                                                      signing_timestamp_now())
        for _ in range(SETUP_REPEATS):
            conn.send(setup)
        conn.signer = Signer(key)
        signed, start = 0, time.monotonic()
        while time.monotonic() - start < confirm_s and signed < confirm_heartbeats:
            signed += sum(m.get_type() == "HEARTBEAT" and (m.get_srcSystem(), m.get_srcComponent())
                          == (ap.system_id, ap.component_id) for m in conn.recv(0.1))
        refused = conn.counters["unsigned"] + conn.counters["bad_signature"]
    finally:
        conn.close()
    name = f"system {ap.system_id} ({ap.as_dict()['autopilot']})"
    clear = "" if endpoint.loopback else f" (the key crossed {endpoint} in clear)"
    if signed >= confirm_heartbeats:
        return True, f"signing set up: {name} signs its frames with the key{clear}"
    return False, (f"{name} does not sign with the key {confirm_s:g} s after SETUP_SIGNING ({refused} frames "
                   f"refused): it does not support MAVLink 2 signing, or refused the key (ArduPilot "
                   f"refuses while armed){clear}")


def setup_from_args(args: argparse.Namespace) -> tuple[bool, str]:
    if not args.signing_key_file:
        raise UserError("--setup-signing needs --signing-key-file KEY")
    if args.target_system is not None and not 1 <= args.target_system <= 255:
        raise UserError(f"--target-system {args.target_system}: must be 1..255")
    if not (math.isfinite(args.discovery_timeout_s) and args.discovery_timeout_s > 0):
        raise UserError(f"--discovery-timeout-s {args.discovery_timeout_s}: must be a positive number")
    return setup_signing(args.master, read_signing_key(args.signing_key_file), args.target_system,
                         args.component_id, args.discovery_timeout_s)
