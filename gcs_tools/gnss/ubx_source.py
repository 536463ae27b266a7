"""u-blox UBX logs as a ``GnssInput`` (``read_ubx_file``). The stream source itself (a file, a serial port
or a TCP stream, through ``pyubx2``) lives in ``companion.receiver.ubx_stream`` (the companion reads
its own receiver); ``open_stream`` and ``ubx_items`` are re-exported here.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from companion.errors import UserError
from companion.gnss.ephemeris import EphemerisStore, GlonassEphemeris, KeplerEphemeris, attach_broadcast
from companion.gnss.observations import GnssEpoch
from companion.gnss.ubx import ReceiverPvt, UbxDecoder
from companion.receiver.ubx_stream import open_stream, ubx_items

__all__ = ["open_stream", "read_ubx_file", "ubx_items"]


def read_ubx_file(path: Path) -> Any:
    """A UBX log as a ``GnssInput``: RAWX epochs with satellite states from the SFRBX ephemerides
    decoded in the same log (GPS, GLONASS, Galileo, BeiDou: observations of satellites without one
    are counted as no_ephemeris, those whose ephemeris broadcasts no accuracy prediction as
    no_accuracy_prediction)."""
    from gcs_tools.gnss.sources import GnssInput

    dec = UbxDecoder()
    epochs: list[GnssEpoch] = []
    ephs: list[KeplerEphemeris] = []
    glo: list[GlonassEphemeris] = []
    pvts: list[ReceiverPvt] = []
    with open_stream(str(path)) as f:
        for item in ubx_items(f, dec):
            if isinstance(item, GnssEpoch):
                epochs.append(item)
            elif isinstance(item, KeplerEphemeris):
                ephs.append(item)
            elif isinstance(item, GlonassEphemeris):
                glo.append(item)
            else:
                pvts.append(item)
    if not epochs:
        raise UserError(f"{path}: no RXM-RAWX epochs (counters: {dict(dec.counters) or 'none'})")
    if not ephs and not glo:
        raise UserError(f"{path}: no ephemeris (RXM-SFRBX of GPS, GLONASS, Galileo, BeiDou) in the log")
    store = EphemerisStore(ephs, glo, dec.klobuchar)
    rejected: Counter[str] = Counter(dec.counters)
    out = []
    for e in epochs:
        e, _ = attach_broadcast(e, store, rejected)
        if e.n:
            out.append(e)
    if not out:
        raise UserError(f"{path}: no RAWX observation has an ephemeris")
    return GnssInput(path, "ubx", out, dec.klobuchar, rejected, store=store)
