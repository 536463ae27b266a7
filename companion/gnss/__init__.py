"""Raw GNSS: observations, time scales, broadcast ephemerides, single-point solution. Pure numpy,
no I/O (readers live in ``gcs_tools.gnss``); imports nothing of mission, MAVLink or telemetry.

    from companion.gnss import GnssEpoch, EphemerisStore, SppConfig, solve_position
    epoch, dropped = attach_broadcast(epoch, store)      # raw pseudoranges: satellite states
    sol = solve_position(epoch, SppConfig(raim=True), klobuchar=store.klobuchar)

Modules: ``systems`` (System codes), ``timescale`` (GPS/UTC/BDT/GLONASS/boot time),
``observations`` (GnssEpoch), ``ephemeris`` (Kepler + GLONASS orbits, EphemerisStore),
``geometry`` (Sagnac range, az/el, geodetic), ``atmosphere`` (Klobuchar, Saastamoinen),
``spp`` (weighted least squares, RAIM/FDE, Doppler velocity), ``lnav`` (GPS LNAV subframes),
``ubx`` (u-blox messages -> epochs), ``fix`` (a solution as a ``GnssFix``).
"""

from companion.gnss.ephemeris import (
    EphemerisStore,
    GlonassEphemeris,
    KeplerEphemeris,
    SatStates,
    attach_broadcast,
    transmission_states,
)
from companion.gnss.observations import GnssEpoch, make_epoch
from companion.gnss.spp import Dops, SppConfig, SppSolution, solve_position
from companion.gnss.systems import System, sv_name

__all__ = [
    "Dops",
    "EphemerisStore",
    "GlonassEphemeris",
    "GnssEpoch",
    "KeplerEphemeris",
    "SatStates",
    "SppConfig",
    "SppSolution",
    "System",
    "attach_broadcast",
    "make_epoch",
    "solve_position",
    "sv_name",
    "transmission_states",
]
