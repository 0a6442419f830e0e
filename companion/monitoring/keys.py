"""The Zenoh key space (documented in docs/monitoring.md)."""

from __future__ import annotations

PREFIX = "companion"
#: Published topics: JSON payloads, except ``preview`` (a JPEG).
TOPICS = ("status", "pose", "tracks", "events", "preview")
#: Queryables answered by a running companion (JSON).
QUERYABLES = ("config", "landmarks")


def key_for(vehicle_id: str, topic: str) -> str:
    """``companion/<vehicle>/<topic>``."""
    return f"{PREFIX}/{vehicle_id}/{topic}"


def vehicle_of(key: str) -> tuple[str, str] | None:
    """Split ``companion/<vehicle>/<topic>`` into (vehicle, topic), or None if foreign."""
    parts = key.split("/")
    if len(parts) != 3 or parts[0] != PREFIX:
        return None
    return parts[1], parts[2]
