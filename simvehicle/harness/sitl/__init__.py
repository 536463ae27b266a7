"""Our simulated vehicle as SITL: the vehicle, estimator and bridge processes (launcher, supervisor),
their outcome, the Zenoh vehicle id, and the run turned into a ``FlightResult`` (``result``)."""
