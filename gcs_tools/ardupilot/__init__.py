"""ArduPilot tools: the ArduCopter SITL launcher (sitl.py)."""
