"""Zenoh telemetry recorder (JSON Lines) and the reader that turns a recording back into series."""
