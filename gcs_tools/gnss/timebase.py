"""A flight log's boot time joined to GPS time: (GPS time, boot µs) pairs from the log.

* tlog: SYSTEM_TIME (``time_unix_usec`` UTC, ``time_boot_ms``);
* PX4 ULog: ``vehicle_gps_position`` / ``sensor_gps`` (``time_utc_usec`` UTC, ``timestamp`` boot µs);
* ArduPilot DataFlash: GPS (``GWk``, ``GMS`` GPS time, ``TimeUS`` boot µs) through pymavlink.
UTC is turned into GPS time with the leap-second table (:mod:`companion.gnss.timescale`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from companion.errors import UserError
from companion.gnss.timescale import BootTimeMap, gps_from_week_tow
from gcs_tools.replay.logs import detect_format


def log_time_map(path: Path) -> BootTimeMap:
    fmt = detect_format(path)
    if fmt == "tlog":
        from companion.mavlink.tlog import read_tlog

        pairs = [
            (m.time_unix_usec, m.time_boot_ms * 1000.0) for _, m in read_tlog(path, types=("SYSTEM_TIME",))
        ]
        what = "SYSTEM_TIME"
        if pairs:
            a = np.array(pairs, dtype=float)
            return BootTimeMap.from_system_time(a[:, 0], a[:, 1])
    elif fmt == "ulog":
        from pyulog import ULog

        what = "vehicle_gps_position/sensor_gps time_utc_usec"
        ulog = ULog(str(path), ["vehicle_gps_position", "sensor_gps"], disable_str_exceptions=True)
        for d in ulog.data_list:
            if "time_utc_usec" in d.data:
                return BootTimeMap.from_system_time(d.data["time_utc_usec"], d.data["timestamp"])
    else:
        from pymavlink import DFReader

        what = "GPS GWk/GMS"
        log = DFReader.DFReader_binary(str(path))
        gps, boot = [], []
        while True:
            m = log.recv_match(type="GPS")
            if m is None:
                break
            if getattr(m, "I", 0) == 0 and m.GWk > 0:
                gps.append(gps_from_week_tow(int(m.GWk), m.GMS / 1e3))
                boot.append(float(m.TimeUS))
        if gps:
            return BootTimeMap.from_gps_pairs(np.array(gps), np.array(boot))
    raise UserError(f"{path}: no {what} in the {fmt} log to join GNSS time to its boot time")
