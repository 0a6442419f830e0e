"""Live monitoring over Eclipse Zenoh: what the companion publishes and who reads it."""

from companion.monitoring.config import MonitorConfig
from companion.monitoring.keys import TOPICS, key_for, vehicle_of
from companion.monitoring.publisher import MonitorPublisher
from companion.monitoring.watcher import FleetView, MonitorWatcher

__all__ = [
    "TOPICS",
    "FleetView",
    "MonitorConfig",
    "MonitorPublisher",
    "MonitorWatcher",
    "key_for",
    "vehicle_of",
]
