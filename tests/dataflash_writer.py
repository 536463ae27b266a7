"""A tiny ArduPilot DataFlash writer for tests: FMT messages, then data messages packed by the format
characters (pymavlink's ``FORMAT_TO_STRUCT``); values are given in the log's units (e.g. degrees,
metres, m/s) and stored scaled as the format says (``c``/``C``/``e``/``E``: ×100, ``L``: ×1e7).

Layouts of ArduCopter 3.2 (``libraries/DataFlash/DataFlash.h`` and ``ArduCopter/Log.pde`` at
Copter-3.2, as logs of that release show them): ``OLD_FORMATS``.
"""

from __future__ import annotations

import struct

from pymavlink.DFReader import FORMAT_TO_STRUCT

HEAD = b"\xa3\x95"
FMT_TYPE = 128

# name: (type, format, columns) of ArduCopter 3.2
OLD_FORMATS = {
    "PARM": (129, "Nf", "Name,Value"),
    "GPS": (130, "BIHBcLLeeEefI", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T"),
    "IMU": (131, "IffffffII", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA"),
    "SIM": (139, "IccCfLL", "TimeMS,Roll,Pitch,Yaw,Alt,Lat,Lng"),
    "ATT": (1, "IccccCCCC", "TimeMS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw"),
}
# ArduCopter 3.1's GPS: no vertical speed, no boot time (its TimeMS is the GPS time of week)
GPS_3_1 = (130, "BIHBcLLeeEe", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs")


class DataFlashWriter:
    def __init__(self) -> None:
        self.data = bytearray()
        self.types: dict[str, tuple[int, str, struct.Struct]] = {}
        self.define(FMT_TYPE, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")

    def define(self, mtype: int, name: str, fmt: str, columns: str) -> None:
        layout = struct.Struct("<" + "".join(FORMAT_TO_STRUCT[c][0] for c in fmt))
        self.types[name] = (mtype, fmt, layout)
        self.data += HEAD + bytes((FMT_TYPE,)) + struct.pack(
            "<BB4s16s64s", mtype, 3 + layout.size, name.encode(), fmt.encode(), columns.encode())

    def add(self, name: str, *values: float | int | str) -> None:
        mtype, fmt, layout = self.types[name]
        raw: list[object] = []
        for c, v in zip(fmt, values, strict=True):
            scale = FORMAT_TO_STRUCT[c][1]
            if isinstance(v, str):
                raw.append(v.encode())
            elif scale is not None:
                raw.append(round(v / scale))
            else:
                raw.append(v)
        self.data += HEAD + bytes((mtype,)) + layout.pack(*raw)
