"""``beliefnav top``: terminal view of live telemetry (rich), for use over SSH."""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
from typing import Any

from rich.console import Group
from rich.live import Live
from rich.markup import escape  # "[s]", "[m]" in headers are units, not rich markup
from rich.table import Table

from companion.telemetry import pubsub as telemetry
from gcs_tools.choices import run_time_s
from gcs_tools.dashboard.labels import headline
from gcs_tools.dashboard.state import FIX_TYPES, STALE_S, LiveState, ended


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration-s", type=run_time_s, default=0.0,
                        help="stop after this long (0: until Ctrl-C)")
    parser.add_argument("--rate-hz", type=float, default=10.0, help="screen refresh rate")
    telemetry.add_arguments(parser)


def _f(x: Any, fmt: str) -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, fmt)


def _state(s: dict[str, Any]) -> str:
    """live / ended (after a clean finish) / stale N s, as the dashboard's badge."""
    age = s["age_s"]
    if age < STALE_S:
        return "[green]live[/]"
    if ended(s["at_goal"], s["status"]):
        return f"ended{' at goal' if s['at_goal'] else ''} {age:.0f} s"
    return f"[yellow]stale {age:.0f} s[/]"


def _gps(s: dict[str, Any]) -> str:
    fix = s.get("fix_type")
    if fix is None:
        return "–"
    sats = s.get("satellites")
    return FIX_TYPES.get(fix, f"type {fix}") + (f", {sats} sats" if sats is not None and sats < 255 else "")


def render(state: LiveState) -> Group:
    """One table of headline numbers per vehicle (what a ground station shows first, then the
    belief), one of the key counters with their labels, one line of malformed payloads."""
    summary = state.summary()
    main = Table(title="beliefnav vehicles", expand=True)
    for col in ("vehicle", "state", "mode", "GPS", "t [s]", "method", "β [0–1]", "NIS [χ²]", "est. error [m]",
                "GNSS latency [s]", "altitude [m]", "messages [count]"):
        main.add_column(escape(col), justify="left" if col in ("method", "state", "mode", "GPS") else "right")
    counters = Table(title="counters", expand=True)
    for col in ("vehicle", "process", "counter", "value [count]"):
        counters.add_column(escape(col), justify="right" if col.startswith("value") else "left")
    for name, s in sorted(summary.items()):
        armed = s.get("armed")
        mode = s.get("mode", "–") + ("" if armed is None else " armed" if armed else " disarmed")
        main.add_row(name, _state(s), mode, _gps(s), _f(s.get("t_s"), ".2f"), s.get("method", "–"),
                     _f(s.get("beta"), ".3f"), _f(s.get("nis"), ".2f"), _f(s.get("est_error_m"), ".2f"),
                     _f(s.get("gnss_latency_s"), ".2f"), _f(s.get("altitude_m"), ".1f"),
                     str(sum(s["messages"].values())))
        for proc, cs in sorted(s["counters"].items()):
            for label, n, alarm in headline(cs):
                counters.add_row(name, proc, label, f"[bold red]{n}[/]" if alarm else str(n))
    bad = sum(state.malformed.values())
    note = f"malformed payloads: {bad}" + (f" (last: {state.last_malformed})" if bad else "")
    return Group(main, counters, f"[bold red]{note}[/]" if bad else note)


def run(args: argparse.Namespace) -> int:
    state = LiveState(history_len=1)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with telemetry.TelemetrySubscriber(state.ingest, telemetry.config_from_args(args),
                                       on_malformed=state.ingest_malformed):
        print("top: subscribed to beliefnav/**", file=sys.stderr, flush=True)
        period = 1.0 / max(args.rate_hz, 0.1)
        remaining = args.duration_s if args.duration_s > 0 else math.inf
        with Live(render(state), refresh_per_second=args.rate_hz, screen=False) as live:
            try:
                while not stop.is_set() and remaining > 0:
                    stop.wait(min(period, remaining))
                    remaining -= period
                    state.take_frame()  # keep the (length-1) histories from growing pending lists
                    live.update(render(state))
            except KeyboardInterrupt:
                pass
    return 0
