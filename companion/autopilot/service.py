"""The companion process beside a real autopilot: options in, the socket loop, truthful endings.

- ``run``: open ``--out`` (a file there, or a directory that cannot be made, is a one-line
  error), the connection (signed with ``--signing-key-file``; a loud warning on stderr and in
  the summary when a link that is not loopback runs unsigned), then :func:`serve` until
  ``--duration-s``, Ctrl-C or SIGTERM (read between messages: the run ends whole, and a second signal
  ends it at once). ``summary.json`` is rewritten every second (atomically:
  a ``kill -9`` leaves the one of the last second) and at the end.
- Endings: no autopilot within ``--discovery-timeout-s`` is a one-line error (exit 2, with the
  frames refused for want of a signature when signing is on: the usual reason); an autopilot
  silent for ``--lost-timeout-s`` is lost: ``summary.failure`` and ``problems`` say so and the
  process ends with exit 1 and one line; otherwise ``failure`` is None (exit 0).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any, NoReturn

from companion.autopilot.connection import open_connection, parse_connection
from companion.autopilot.discovery import DiscoveryConfig
from companion.autopilot.node import AutopilotCompanion, CompanionConfig
from companion.autopilot.translate import TranslateConfig
from companion.domain.geodesy import parse_home
from companion.errors import UserError
from companion.estimator.freespace import FreeSpaceConfig
from companion.mavlink.signing import read_signing_key
from companion.mission import load_mission
from companion.receiver.raw_receiver import RawReceiver
from companion.runtime import StopRequest, stop_on_signals, write_json
from companion.telemetry.pubsub import TelemetryPublisher

UNSIGNED_WARNING = ("WARNING: MAVLink signing is OFF on {link}, which is not loopback: anyone who can "
                    "send on it can forge the autopilot's frames and steer this estimate (and what "
                    "--feed sends back). Give --signing-key-file (see docs/autopilot.md, Signing).")


def config_from_args(args: argparse.Namespace) -> CompanionConfig:
    if args.out is None:
        raise UserError("--out DIR is required with --master")
    delay = args.gps_delay_ms
    if delay is not None and not (math.isfinite(delay) and 0 <= delay <= 1000):
        raise UserError(f"--gps-delay-ms {delay}: must be within 0..1000")
    lag = getattr(args, "clock_lag_ms", None)
    if lag is not None and not (math.isfinite(lag) and 0 <= lag <= 1000):
        raise UserError(f"--clock-lag-ms {lag}: must be within 0..1000")
    target = args.target_system
    if target is not None and not 1 <= target <= 255:
        raise UserError(f"--target-system {target}: must be 1..255")
    key_file = getattr(args, "signing_key_file", None)
    coupling, ubx = getattr(args, "coupling", "loose"), getattr(args, "ubx", None)
    if coupling == "tight" and ubx is None:
        raise UserError("--coupling tight needs the receiver: --ubx serial:DEVICE:BAUD or tcp:HOST:PORT")
    if coupling != "tight" and ubx is not None:
        raise UserError("--ubx goes with --coupling tight (the loose filter takes the autopilot's fixes)")
    mission = load_mission(args.mission) if getattr(args, "mission", None) else None
    if getattr(args, "free_space", False) and mission is None:
        raise UserError("--free-space needs --mission (the buildings an estimate may not be inside)")
    home = parse_home(args.home) if args.home else None if mission is None else mission.frame
    return CompanionConfig(
        master=args.master, out_dir=Path(args.out), method=args.method, feed=args.feed,
        coupling=coupling, ubx=ubx, mission=mission,
        free_space=FreeSpaceConfig() if getattr(args, "free_space", False) else None,
        clock_lag_us=None if lag is None else round(lag * 1000),
        home=home, duration_s=args.duration_s,
        component_id=args.component_id, discovery_timeout_s=args.discovery_timeout_s,
        signing_key=read_signing_key(key_file) if key_file else None,
        discovery=DiscoveryConfig(target_system=target, lost_timeout_s=args.lost_timeout_s),
        translate=TranslateConfig(gnss_instance=args.gnss_instance,
                                  gnss_delay_us=None if delay is None else round(delay * 1000)))


def prepare_out_dir(path: Path, option: str = "--out") -> None:
    """``path`` as a directory we can write in (created), or a one-line UserError."""
    if path.exists() and not path.is_dir():
        raise UserError(f"{option} {path}: exists and is not a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{option} {path}: cannot create the directory: {exc.strerror or exc}") from None
    probe = path / ".write-test"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise UserError(f"{option} {path}: cannot write there: {exc.strerror or exc}") from None


def security_note(config: CompanionConfig) -> dict[str, Any]:
    """What protects the link (for the summary), with the warning when nothing does."""
    endpoint = parse_connection(config.master)
    signed = config.signing_key is not None
    warning = None if signed or endpoint.loopback else UNSIGNED_WARNING.format(link=endpoint)
    return {"signing": signed, "loopback": endpoint.loopback, "warning": warning}


def run(config: CompanionConfig, telemetry: TelemetryPublisher | None = None) -> dict[str, Any]:
    """Run until ``duration_s`` (or Ctrl-C/SIGTERM, or the autopilot is lost); write run.tlog and
    summary.json; the summary (``failure``: why the run failed, None when it did not; ``stop_signal``:
    SIGINT or SIGTERM when one ended it, else None)."""

    prepare_out_dir(config.out_dir)
    security = security_note(config)
    if security["warning"]:
        print(f"beliefnav: {security['warning']}", file=sys.stderr)
    receiver = RawReceiver(config.ubx) if config.coupling == "tight" and config.ubx else None
    conn = open_connection(config.master, 1, config.component_id, config.out_dir / "run.tlog",
                           signing_key=config.signing_key, peers=config.peers)
    node = AutopilotCompanion(config, conn, telemetry)
    start = time.monotonic()
    failure: str | None = None
    with stop_on_signals() as stop:  # through the ending too: one signal never cuts the summary short

        def summary() -> dict[str, Any]:
            extra = {} if receiver is None else {"receiver": {"url": config.ubx, **receiver.counters()}}
            return (node.summary(time.monotonic() - start)
                    | {"security": security, "failure": failure, "stop_signal": stop.name} | extra)

        try:
            failure = serve(node, start, lambda: write_json(config.out_dir / "summary.json", summary()),
                            receiver, stop)
        finally:
            if failure is None:
                node.finish()  # a clean end (duration, Ctrl-C, SIGTERM): the ground tools say "ended"
            result = summary()
            write_json(config.out_dir / "summary.json", result)
            if receiver is not None:
                receiver.close()
            conn.close()
            if conn.tlog is not None:
                conn.tlog.close()
    return result


def _no_heartbeat(node: AutopilotCompanion, waited_s: float) -> NoReturn:
    """No autopilot found in ``waited_s``: one line (exit 2), naming frames refused for their signature."""
    node.errors.append("no autopilot HEARTBEAT")
    refused = sum(node.conn.counters[k] for k in ("unsigned", "bad_signature", "replayed"))
    hint = (f" ({refused} frames refused: not signed with our key; is signing set up on the "
            "autopilot? see --setup-signing)" if refused else "")
    raise UserError(f"--master {node.config.master}: no autopilot HEARTBEAT within {waited_s:g} s" + hint)


def serve(node: AutopilotCompanion, start_s: float, checkpoint: Any = None,
          receiver: RawReceiver | None = None, stop: StopRequest | None = None) -> str | None:
    """The loop; returns why the run failed (the autopilot lost) or None. ``checkpoint()`` is called
    every ``summary_period_s`` (it rewrites summary.json). ``receiver`` (``--coupling tight``): its
    decoded items are handed to the node between MAVLink messages. ``stop``: once it holds a signal,
    the loop ends before its next turn (within one receive wait, 20 ms, or a lost link's reconnection
    attempt, at most 2 s)."""
    c = node.config
    next_checkpoint = start_s + c.summary_period_s
    while True:
        if stop:
            return None
        now = time.monotonic()
        d = node.discovery
        if c.duration_s is not None and now - start_s >= c.duration_s:
            if d.autopilot is None:  # the run's time is up before any autopilot was found: not a success
                _no_heartbeat(node, min(c.duration_s, c.discovery_timeout_s))
            return None
        if d.autopilot is None and now - start_s > c.discovery_timeout_s:
            _no_heartbeat(node, c.discovery_timeout_s)
        if d.given_up(now):
            ap = d.autopilot
            assert ap is not None
            reason = (f"the autopilot (system {ap.system_id}) has been silent for "
                      f"{now - d.last_heartbeat_s:.0f} s: lost")
            node.problem("autopilot_lost", reason)
            return reason
        node.tick(now)
        for msg in node.conn.recv(timeout_s=0.02):
            node.handle(msg, time.monotonic())
        if receiver is not None:
            node.set_klobuchar(receiver.decoder.klobuchar)
            node.raw_items(receiver.drain())
        if checkpoint is not None and now >= next_checkpoint:
            next_checkpoint = now + c.summary_period_s
            checkpoint()
