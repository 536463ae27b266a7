"""Zenoh telemetry: JSON codec per topic (``codec``) and publisher/subscriber (``pubsub``)."""
