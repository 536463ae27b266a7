"""``beliefnav record --out FILE``: every telemetry message on Zenoh, appended to a JSON Lines file."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time

from companion.telemetry import pubsub as telemetry
from gcs_tools.choices import run_time_s
from gcs_tools.recorder.recording import RecordingWriter


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="runs/record.jsonl",
                        help="recording file (JSON Lines, see README; default runs/record.jsonl)")
    parser.add_argument("--duration-s", type=run_time_s, default=0.0,
                        help="stop after this long (0: until Ctrl-C)")
    parser.add_argument("--key", default="beliefnav/**", help="Zenoh key expression to record")
    telemetry.add_arguments(parser)


def run(args: argparse.Namespace) -> int:
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    writer = RecordingWriter(args.out)
    try:
        sub = telemetry.TelemetrySubscriber(
            writer.write, telemetry.config_from_args(args), key_expr=args.key,
            on_malformed=lambda key, payload, err: writer.write_malformed(key, payload, err, time.time_ns()))
        try:
            print(f"recording {args.key} to {args.out}", flush=True)
            deadline = time.monotonic() + args.duration_s if args.duration_s > 0 else float("inf")
            while not stop.is_set() and time.monotonic() < deadline:
                stop.wait(min(1.0, max(deadline - time.monotonic(), 0.0)))
                writer.flush()
        except KeyboardInterrupt:
            pass
        finally:
            sub.close()
    finally:
        writer.close()
    print(f"recorded {writer.count} messages ({writer.malformed} malformed) to {args.out}", file=sys.stderr)
    return 0
