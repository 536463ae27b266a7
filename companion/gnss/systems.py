"""Satellite systems: one integer code per system (u-blox ``gnssId`` numbering) and RINEX letters."""

from __future__ import annotations

from enum import IntEnum

import numpy as np


class System(IntEnum):
    """Satellite system; the values are u-blox ``gnssId`` (UBX RXM-RAWX, NAV-SAT)."""

    GPS = 0
    SBAS = 1
    GALILEO = 2
    BEIDOU = 3
    QZSS = 5
    GLONASS = 6


RINEX_LETTER: dict[System, str] = {
    System.GPS: "G",
    System.SBAS: "S",
    System.GALILEO: "E",
    System.BEIDOU: "C",
    System.QZSS: "J",
    System.GLONASS: "R",
}
FROM_RINEX_LETTER: dict[str, System] = {v: k for k, v in RINEX_LETTER.items()}
SHORT_NAME: dict[System, str] = {
    System.GPS: "GPS",
    System.SBAS: "SBAS",
    System.GALILEO: "GAL",
    System.BEIDOU: "BDS",
    System.QZSS: "QZS",
    System.GLONASS: "GLO",
}

# Satellites on Keplerian broadcast orbits (GLONASS broadcasts a state vector; SBAS neither here)
KEPLER_SYSTEMS = (System.GPS, System.GALILEO, System.BEIDOU, System.QZSS)


def sv_name(system: int, prn: int) -> str:
    """RINEX satellite name, e.g. ``G05``, ``R24``, ``C01``."""
    return f"{RINEX_LETTER[System(system)]}{int(prn):02d}"


def sv_key(system: np.ndarray | int, prn: np.ndarray | int) -> np.ndarray | int:
    """One integer per satellite (``system * 1000 + prn``), vectorised: a dictionary/sort key."""
    return (
        np.asarray(system, dtype=np.int64) * 1000 + np.asarray(prn, dtype=np.int64)
        if isinstance(system, np.ndarray)
        else int(system) * 1000 + int(prn)
    )


def is_beidou_geo(prn: np.ndarray) -> np.ndarray:
    """BeiDou GEO satellites (C01-C05 of BDS-2, C59-C63 of BDS-3): their own orbit transformation."""
    prn = np.asarray(prn)
    return (prn <= 5) | ((prn >= 59) & (prn <= 63))
