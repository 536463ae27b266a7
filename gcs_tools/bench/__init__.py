"""Benchmarks: measured figures printed as JSON, never asserted in timed tests."""
