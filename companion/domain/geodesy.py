"""Geodetic <-> local NED about a fixed home point (WGS-84, via pymap3d)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pymap3d
from numpy.typing import ArrayLike


@dataclass(frozen=True, slots=True)
class LocalNedFrame:
    """A local north-east-down frame tangent at ``home`` (degrees, degrees, metres)."""

    home_lat_deg: float
    home_lon_deg: float
    home_alt_m: float

    def to_ned_m(self, lat_deg: ArrayLike, lon_deg: ArrayLike, alt_m: ArrayLike) -> np.ndarray:
        """(3,) for scalars; (3, N) for arrays of N points."""
        n, e, d = pymap3d.geodetic2ned(
            lat_deg, lon_deg, alt_m, self.home_lat_deg, self.home_lon_deg, self.home_alt_m
        )
        return np.array([n, e, d], dtype=float)

    def to_geodetic(self, p_ned_m: np.ndarray) -> tuple[float, float, float]:
        lat, lon, alt = pymap3d.ned2geodetic(
            float(p_ned_m[0]), float(p_ned_m[1]), float(p_ned_m[2]),
            self.home_lat_deg, self.home_lon_deg, self.home_alt_m,
        )
        return float(lat), float(lon), float(alt)


def parse_home(text: str, option: str = "--home") -> LocalNedFrame:
    """``"lat,lon,alt"`` (degrees, degrees, metres AMSL) -> frame; a one-line UserError otherwise."""
    import math

    from companion.errors import UserError

    try:
        lat, lon, alt = (float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"{option} {text!r}: expected lat,lon,alt (degrees, degrees, metres)") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and math.isfinite(alt)):
        raise UserError(f"{option} {text!r}: latitude/longitude out of range")
    return LocalNedFrame(lat, lon, alt)
