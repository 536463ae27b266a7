"""Physical and system constants (SI units; names carry the unit).

Sources: IS-GPS-200 (GPS, QZSS), Galileo OS SIS ICD, BeiDou ICD B1I, GLONASS ICD 5.1 (PZ-90.11).
"""

from __future__ import annotations

C_M_S = 299_792_458.0  # speed of light in vacuum

# WGS-84 ellipsoid (geodesy; PZ-90.11 differs by centimetres, ignored here)
WGS84_A_M = 6_378_137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)

# Earth rotation rate and gravitational constant as each system's broadcast orbit model uses them
OMEGA_E_GPS_RAD_S = 7.2921151467e-5
MU_GPS_M3_S2 = 3.986005e14
OMEGA_E_GAL_RAD_S = 7.2921151467e-5
MU_GAL_M3_S2 = 3.986004418e14
OMEGA_E_BDS_RAD_S = 7.2921150e-5
MU_BDS_M3_S2 = 3.986004418e14
OMEGA_E_GLO_RAD_S = 7.292115e-5
MU_GLO_M3_S2 = 3.9860044e14
J2_GLO = 1.0826257e-3
A_E_GLO_M = 6_378_136.0

# Sagnac (Earth rotation during the signal's flight) in the receiver's geometry: one rate for all
OMEGA_E_RAD_S = OMEGA_E_GPS_RAD_S

# Carrier frequencies of the signals the readers take (Hz)
FREQ_L1_HZ = 1_575.42e6  # GPS L1 C/A, Galileo E1, QZSS L1, SBAS L1
FREQ_B1I_HZ = 1_561.098e6  # BeiDou B1I
FREQ_G1_HZ = 1_602.0e6  # GLONASS G1 FDMA centre: channel k at FREQ_G1_HZ + k * DFREQ_G1_HZ
DFREQ_G1_HZ = 0.5625e6

SECONDS_PER_WEEK = 604_800
