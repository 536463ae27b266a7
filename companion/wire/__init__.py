"""The wire contract shared by vehicle, companion and ground tools.

``samples``: domain types that cross process boundaries (timestamped, frames and units in
names). Codecs (MAVLink, Zenoh) translate between these and bytes; nothing else does.
"""
