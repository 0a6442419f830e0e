"""The watching side: every vehicle's latest monitoring data, from any process.

Zenoh delivers samples on its own threads; :class:`MonitorWatcher` stores them under a lock
and hands out immutable snapshots (:class:`FleetView`), so readers never see a half-written
update and never block Zenoh.
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import zenoh

from companion.monitoring.config import MonitorConfig, open_session
from companion.monitoring.keys import PREFIX, key_for, vehicle_of

EVENTS_KEPT = 20
#: Pose payloads kept per vehicle for plots (a minute at 50 Hz).
HISTORY_KEPT = 3000


@dataclass(frozen=True)
class VehicleView:
    """What is known of one vehicle: latest JSON per topic, receive times, last events."""

    vehicle_id: str
    latest: Mapping[str, Any]
    received_s: Mapping[str, float]
    counts: Mapping[str, int]
    events: tuple[Any, ...]
    preview_jpeg: bytes | None
    pose_history: tuple[tuple[float, Any], ...] = ()

    def age_s(self, topic: str, now_s: float | None = None) -> float | None:
        """Seconds since ``topic`` last arrived (None if never): stale data shows its age."""
        if topic not in self.received_s:
            return None
        return (time.monotonic() if now_s is None else now_s) - self.received_s[topic]


@dataclass(frozen=True)
class FleetView:
    """A consistent snapshot of every vehicle seen."""

    vehicles: Mapping[str, VehicleView] = field(default_factory=dict)
    malformed: int = 0


@dataclass
class _Vehicle:
    latest: dict[str, Any] = field(default_factory=dict)
    received_s: dict[str, float] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    events: deque[Any] = field(default_factory=lambda: deque(maxlen=EVENTS_KEPT))
    preview: bytes | None = None
    pose_history: deque[tuple[float, Any]] = field(
        default_factory=lambda: deque(maxlen=HISTORY_KEPT))


class MonitorWatcher:
    """Subscribes to ``companion/<vehicle or *>/*`` and keeps the latest of everything."""

    def __init__(self, cfg: MonitorConfig, vehicle_id: str = "*") -> None:
        self.session = open_session(cfg)
        self._lock = threading.Lock()
        self._vehicles: dict[str, _Vehicle] = {}
        self._malformed = 0
        self._arrived = threading.Condition(self._lock)
        self._sub = self.session.declare_subscriber(
            f"{PREFIX}/{vehicle_id}/*", self._on_sample
        )

    def _on_sample(self, sample: zenoh.Sample) -> None:
        parsed = vehicle_of(str(sample.key_expr))
        payload = sample.payload.to_bytes()
        with self._lock:
            if parsed is None:
                self._malformed += 1
                return
            vehicle, topic = parsed
            state = self._vehicles.setdefault(vehicle, _Vehicle())
            if topic == "preview":
                state.preview = payload
            else:
                try:
                    value = json.loads(payload)
                except ValueError:
                    self._malformed += 1
                    return
                state.latest[topic] = value
                if topic == "events":
                    state.events.append(value)
                elif topic == "pose":
                    state.pose_history.append((time.monotonic(), value))
            state.received_s[topic] = time.monotonic()
            state.counts[topic] = state.counts.get(topic, 0) + 1
            self._arrived.notify_all()

    def snapshot(self) -> FleetView:
        """The current view of every vehicle."""
        with self._lock:
            return FleetView(
                {
                    vid: VehicleView(vid, dict(v.latest), dict(v.received_s), dict(v.counts),
                                     tuple(v.events), v.preview, tuple(v.pose_history))
                    for vid, v in self._vehicles.items()
                },
                self._malformed,
            )

    def wait_for(self, topic: str, vehicles: int = 1, timeout_s: float = 10.0) -> bool:
        """Block until ``vehicles`` distinct vehicles have sent ``topic`` (or time out)."""
        deadline = time.monotonic() + timeout_s
        with self._lock:
            while sum(topic in v.received_s for v in self._vehicles.values()) < vehicles:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._arrived.wait(remaining)
            return True

    def query(self, vehicle_id: str, name: str, timeout_s: float = 3.0) -> Any:
        """Ask a companion's queryable (``config`` or ``landmarks``); None if no answer."""
        for reply in self.session.get(key_for(vehicle_id, name), timeout=timeout_s):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes())
        return None

    def close(self) -> None:
        """Stop listening and close the session."""
        self._sub.undeclare()
        self.session.close()
