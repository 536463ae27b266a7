"""Physical constants shared by the vehicle, the wire format and the filter (written once)."""

STANDARD_GRAVITY_M_S2 = 9.80665  # standard gravity g₀ (m/s²): 1 g of an IMU, the dynamics, the filter
# |specific force| per axis beyond an IMU's full scale (16 g): damage, wherever a sample enters (m/s²)
MAX_SPECIFIC_FORCE_M_S2 = 16.0 * STANDARD_GRAVITY_M_S2
# |pressure altitude| beyond the standard atmosphere's 1100 hPa to 10 hPa (−700 to 31,000 m): damage (m)
MAX_PRESSURE_ALT_M = 40_000.0
