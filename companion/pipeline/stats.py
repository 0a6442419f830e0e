"""Rolling latency percentiles and rates for the status line and the demo summary."""

from __future__ import annotations

from collections import deque

import numpy as np


class Rolling:
    """The last ``size`` samples of one quantity (e.g. capture -> wire latency in ms)."""

    def __init__(self, size: int = 1000) -> None:
        self._values: deque[float] = deque(maxlen=size)
        self.count = 0

    def add(self, value: float) -> None:
        self._values.append(float(value))
        self.count += 1

    def percentile(self, q: float) -> float | None:
        """The q-th percentile (0..100) of the window, or None when empty."""
        if not self._values:
            return None
        return float(np.percentile(np.fromiter(self._values, float), q))

    def summary(self) -> dict[str, float | None]:
        """``{"min": ..., "p50": ..., "p99": ...}`` rounded to 0.01 (ArduPilot's
        ``VISO_DELAY_MS`` is the least while the p50 is inside EKF3's 60 ms fusion horizon,
        the p50 beyond: docs/mavlink.md, "Timestamps")."""
        if not self._values:
            return {"min": None, "p50": None, "p99": None}
        values = np.percentile(np.fromiter(self._values, float), (0, 50, 99))
        return {k: round(float(v), 2) for k, v in zip(("min", "p50", "p99"), values, strict=True)}


class RateMeter:
    """Events per second over a sliding window of timestamps (seconds)."""

    def __init__(self, window_s: float = 2.0) -> None:
        self.window_s = window_s
        self._times: deque[float] = deque()

    def tick(self, now_s: float) -> None:
        self._times.append(now_s)
        while self._times and now_s - self._times[0] > self.window_s:
            self._times.popleft()

    def rate(self, now_s: float) -> float:
        while self._times and now_s - self._times[0] > self.window_s:
            self._times.popleft()
        if len(self._times) < 2:
            return 0.0
        span = max(now_s - self._times[0], 1e-6)
        return (len(self._times) - 1) / span if span > 0 else 0.0
