"""Pick the reader of a log: an ANSFL flight (a directory with ``IMU_1.csv`` and ``GT.csv``, or
its IMU file), else by the file's first bytes (ULog magic, DataFlash FMT header), else by its
extension (``.ulg``, ``.bin``), else a MAVLink tlog (which has no magic)."""

from __future__ import annotations

from pathlib import Path

from companion.domain.geodesy import LocalNedFrame
from companion.errors import UserError
from gcs_tools.replay.ansfl import AnsflSource, flight_files
from gcs_tools.replay.dataflash import DataFlashSource, is_dataflash
from gcs_tools.replay.events import LogReader
from gcs_tools.replay.tlog_source import TlogSource
from gcs_tools.replay.ulog import ULogSource, is_ulog

FORMATS = ("tlog", "dataflash", "ulog", "ansfl")


def detect_format(path: Path) -> str:
    if flight_files(path) is not None:
        return "ansfl"
    if path.is_dir():
        raise UserError(f"{path}: a directory, but not an ANSFL flight (IMU_1.csv and GT.csv)")
    with open(path, "rb") as f:
        head = f.read(16)
    if is_ulog(head):
        return "ulog"
    if is_dataflash(head):
        return "dataflash"
    suffix = path.suffix.lower()
    if suffix == ".ulg":
        return "ulog"
    if suffix == ".bin":
        return "dataflash"
    return "tlog"


def open_log(path: Path, gps_delay_ms: float | None = None, home: LocalNedFrame | None = None) -> LogReader:
    """The reader of ``path``; ``gps_delay_ms`` overrides a DataFlash log's GPS delay; ``home``
    anchors a log without geodetic positions (ANSFL)."""
    if not path.exists():
        raise UserError(f"{path}: no such file")
    fmt = detect_format(path)
    if gps_delay_ms is not None and fmt != "dataflash":
        raise UserError(f"--gps-delay-ms applies to DataFlash (.bin) logs; {path} is a {fmt} log "
                        "(its fixes carry their validity time)")
    if fmt == "ansfl":
        return AnsflSource(path, home)
    if fmt == "ulog":
        return ULogSource(path)
    if fmt == "dataflash":
        return DataFlashSource(path, gps_delay_ms)
    return TlogSource(path)
