"""``beliefnav dashboard --port P``: live web dashboard on 127.0.0.1 fed by a Zenoh subscriber."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys

from companion.telemetry import pubsub as telemetry
from gcs_tools.choices import run_time_s, tcp_port


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", type=tcp_port, default=8080, help="HTTP port (default 8080)")
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    parser.add_argument("--duration-s", type=run_time_s, default=0.0, help="stop after this long (0: never)")
    telemetry.add_arguments(parser)


async def _main(args: argparse.Namespace) -> None:
    from gcs_tools.dashboard.server import Dashboard, serve  # aiohttp: not for --help
    from gcs_tools.dashboard.state import LiveState

    state = LiveState()
    dashboard = Dashboard(state)
    runner = await serve(dashboard, args.host, args.port)  # before Zenoh: a busy port fails fast
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    sub = telemetry.TelemetrySubscriber(state.ingest, telemetry.config_from_args(args),
                                        on_malformed=state.ingest_malformed)
    try:
        print(f"dashboard on http://{args.host}:{args.port}/", flush=True)
        with_timeout = args.duration_s if args.duration_s > 0 else None
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), with_timeout)
    finally:
        sub.close()
        await runner.cleanup()
    print(f"dashboard: {state.received} messages, {sum(state.malformed.values())} malformed", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    asyncio.run(_main(args))
    return 0
