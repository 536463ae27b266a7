"""Command-line options of the foreign-autopilot mode, kept light (no pymavlink import), so every
companion process can offer them without paying for the adapter's imports."""

from __future__ import annotations

import argparse
from pathlib import Path

DEFAULT_COMPONENT_ID = 197  # MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY
FEEDS = ("none", "vision", "odometry", "gps-input")


def add_master_arguments(parser: argparse.ArgumentParser, master_required: bool,
                         mission: bool = True) -> None:
    """The options of the foreign-autopilot mode (``--master`` and what goes with it); ``mission``: with
    ``--mission`` (False where the parser has its own)."""
    parser.add_argument("--master", required=master_required,
                        help="autopilot connection: tcp:HOST:PORT, udpin:HOST:PORT, udpout:HOST:PORT, "
                             "serial:DEVICE:BAUD")
    parser.add_argument("--out", type=Path, help="output directory (run.tlog, summary.json)")
    parser.add_argument("--feed", default="none", choices=FEEDS, help="what to send the autopilot")
    parser.add_argument("--home", help="local frame origin LAT,LON,ALT (default: the mission's home with "
                                       "--mission, else the autopilot's origin)")
    if mission:
        parser.add_argument("--mission", default=None, metavar="MISSION",
                            help="the mission flown (a packaged name or a mission YAML file): its buildings "
                                 "are the map of the tight filter's line-of-sight prior and of the map "
                                 "methods (docs/autopilot.md)")
    parser.add_argument("--free-space", action="store_true",
                        help="with --mission: an estimate inside a building is fed at its mean outside them "
                             "(docs/autopilot.md; off by default: no gain measured in closed loop)")
    parser.add_argument("--duration-s", type=float, help="stop after this many wall seconds")
    parser.add_argument("--component-id", type=int, default=DEFAULT_COMPONENT_ID,
                        help="our MAVLink component id")
    parser.add_argument("--gnss-instance", type=int, default=1, choices=(1, 2),
                        help="GNSS input: 1 = GPS_RAW_INT, 2 = GPS2_RAW")
    parser.add_argument("--gps-delay-ms", type=float, default=None,
                        help="receiver delay: fix validity = the autopilot's stamp minus this "
                             "(default: the autopilot's GPS1_DELAY_MS / EKF2_GPS_DELAY)")
    parser.add_argument("--coupling", default="loose", choices=("loose", "tight"),
                        help="loose: the autopilot's GNSS fixes into the estimator (default); tight: the "
                             "receiver's raw epochs (--ubx) into the tightly coupled filter (docs/tight.md)")
    parser.add_argument("--ubx", default=None, metavar="URL",
                        help="--coupling tight: the u-blox receiver (RXM-RAWX, RXM-SFRBX): "
                             "serial:DEVICE:BAUD or tcp:HOST:PORT")
    parser.add_argument("--clock-lag-ms", type=float, default=None,
                        help="--coupling tight: how far the autopilot's clock (SYSTEM_TIME) lags GPS time; "
                             "ArduPilot sets it from a fix at the fix's arrival, so by that receiver's "
                             "latency (default: the receiver delay, --gps-delay-ms or the autopilot's)")
    parser.add_argument("--discovery-timeout-s", type=float, default=60.0,
                        help="give up when no autopilot HEARTBEAT arrives within this (wall s)")
    parser.add_argument("--lost-timeout-s", type=float, default=15.0,
                        help="the autopilot silent this long (wall s) is lost: the run ends, exit 1")
    parser.add_argument("--target-system", type=int, default=None,
                        help="the autopilot's MAVLink system id (default: the one the link carries; "
                             "another autopilot is then an alarm)")


def add_signing_argument(parser: argparse.ArgumentParser) -> None:
    """``--signing-key-file`` (the SITL processes get it with their link options instead)."""
    parser.add_argument("--signing-key-file", type=Path,
                        help="MAVLink 2 signing key (64 hex characters or a passphrase, as MAVProxy's): "
                             "sign what we send, refuse what is not signed with it")
