"""Scripted link faults for the fake autopilot: drop, latency + jitter, loss, corrupted bytes.

Faults apply to both directions of the fake's link.  Randomness comes from a
``numpy.random.Generator`` handed in, so a fault script is reproducible from its seed.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass
class FaultState:
    """Current fault settings; change them at any time (the fake reads them per packet)."""

    drop_until_ns: int = 0
    latency_s: float = 0.0
    jitter_s: float = 0.0
    loss_probability: float = 0.0
    corrupt_probability: float = 0.0


@dataclass
class FaultCounters:
    dropped_link_down: int = 0
    lost: int = 0
    corrupted: int = 0
    delayed: int = 0
    #: each HEARTBEAT sent while corruption was on: True where it was corrupted (a run of
    #: them is a heartbeat gap the other side may rightly call a lost link)
    heartbeats_corrupted: list[bool] = field(default_factory=list)


def is_heartbeat(data: bytes) -> bool:
    """A MAVLink 1 or 2 frame of message id 0 (HEARTBEAT)."""
    if len(data) >= 10 and data[0] == 0xFD:
        return data[7] == 0 and data[8] == 0 and data[9] == 0
    return len(data) >= 6 and data[0] == 0xFE and data[5] == 0


class FaultInjector:
    """Pass bytes through ``deliver`` after applying the current :class:`FaultState`."""

    def __init__(self, rng: np.random.Generator, clock_ns: Callable[[], int]) -> None:
        self.state = FaultState()
        self.counters = FaultCounters()
        self._rng = rng
        self._clock_ns = clock_ns
        self._handles: set[asyncio.TimerHandle] = set()

    def link_down(self) -> bool:
        return self._clock_ns() < self.state.drop_until_ns

    def apply(self, data: bytes, deliver: Callable[[bytes], None], corrupt: bool) -> None:
        s = self.state
        if self.link_down():
            self.counters.dropped_link_down += 1
            return
        if s.loss_probability > 0 and self._rng.random() < s.loss_probability:
            self.counters.lost += 1
            return
        if corrupt and s.corrupt_probability > 0:
            hit = bool(self._rng.random() < s.corrupt_probability)
            if is_heartbeat(data):
                self.counters.heartbeats_corrupted.append(hit)
            if hit:
                buf = bytearray(data)
                i = int(self._rng.integers(0, len(buf)))
                buf[i] ^= int(self._rng.integers(1, 256))
                data = bytes(buf)
                self.counters.corrupted += 1
        delay = s.latency_s
        if s.jitter_s > 0:
            delay += float(self._rng.uniform(0.0, s.jitter_s))
        if delay <= 0:
            deliver(data)
            return
        self.counters.delayed += 1
        loop = asyncio.get_running_loop()
        handle: asyncio.TimerHandle

        def fire() -> None:
            self._handles.discard(handle)
            deliver(data)

        handle = loop.call_later(delay, fire)
        self._handles.add(handle)

    def cancel_pending(self) -> None:
        for h in self._handles:
            h.cancel()
        self._handles.clear()
