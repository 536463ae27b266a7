"""Domain types shared by vehicle, companion and ground tools, and the geodesy of the local frame.

``samples``: timestamped records that cross process boundaries (frames and units in names);
``geodesy``: the local NED frame about a home point. Pure: no MAVLink, Zenoh or files, so the
estimator imports them without touching any wire.
"""
