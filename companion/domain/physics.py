"""Physical constants shared by the vehicle, the wire format and the filter (written once)."""

STANDARD_GRAVITY_M_S2 = 9.80665  # standard gravity g₀ (m/s²): 1 g of an IMU, the dynamics, the filter
