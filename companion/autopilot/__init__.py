"""The companion beside a foreign MAVLink autopilot (ArduPilot, PX4).

- :mod:`.connection` — connection strings (``tcp:``, ``udpin:``, ``udpout:``, ``serial:``) parsed in
  one place, and a generic MAVLink connection (pymavlink) that records both directions to a tlog.
- :mod:`.discovery` — the autopilot found by its HEARTBEAT; other systems ignored and counted.
- :mod:`.streams` — what the companion asks the autopilot to send (SET_MESSAGE_INTERVAL, then
  REQUEST_DATA_STREAM), and when to ask again (reboot, silence).
- :mod:`.translate` — the autopilot's messages as domain samples on ONE time base (its boot time).
- :mod:`.timesync` — TIMESYNC as the MAVLink spec says (answer requests, estimate the offset).
- :mod:`.feeds` — what goes back: GPS_INPUT, VISION_POSITION_ESTIMATE, ODOMETRY (ArduPilot frames).
- :mod:`.compare` — our estimate against the autopilot's own (pure numpy).
- :mod:`.node` — the process loop and its outputs (``run.tlog``, ``summary.json``).
"""
