"""The fake autopilot's summary: what it received and did, JSON-serialisable."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from mavlink_bridge.fake_autopilot import FakeAutopilot


def fake_summary(self: FakeAutopilot) -> dict[str, Any]:
    """Everything a test or a user wants to know about ``self``, JSON-serialisable."""
    reasons: dict[str, int] = {}
    for r in self.vision:
        reasons[r.reason] = reasons.get(r.reason, 0) + 1
    periods = np.diff([h.arrival_s for h in self.heartbeats])
    return {
        "profile": self.config.profile,
        "flight_s": self.flight_s(),
        "vision_received": len(self.vision),
        "vision_accepted": len(self.accepted()),
        "vision_reasons": reasons,
        "vision": [r.as_dict() for r in self.vision],
        "landing_targets": self.landing_targets,
        "commands": self.commands,
        "origin": self.origin,
        "timesync_samples": self.timesync_samples,
        "timesync_synced": self.timesync_synced,
        "companion_heartbeats": len(self.heartbeats),
        "heartbeat_period_s": _period_stats(periods),
        "statustexts": self.statustexts,
        "rx": self.codec.rx.as_dict(),
        "faults": vars(self.faults.counters),
        "counters": dict(self.counters),
        "streams_asked": self.streams.asked,
        "flight_events": self.flight.events,
        "statustexts_sent": self.statustexts_sent,
        "estimate_error_m": _error_stats([math.dist(e, t) for _, e, t in self.track]),
        "params_set": self.params.sets,
    }


def _error_stats(errors: list[float]) -> dict[str, float | None]:
    """Median and max of the estimator's distance from the truth (10 Hz samples)."""
    if not errors:
        return {"median": None, "max": None}
    return {"median": float(np.median(errors)), "max": float(np.max(errors))}


def _period_stats(periods: np.ndarray) -> dict[str, float | None]:
    """Median/min/max of the companion's heartbeat periods and the jitter |period - median|."""
    if periods.size == 0:
        return {"median": None, "min": None, "max": None, "jitter_p99": None,
                "jitter_max": None}
    med = float(np.median(periods))
    dev = np.abs(periods - med)
    return {"median": med, "min": float(periods.min()), "max": float(periods.max()),
            "jitter_p99": float(np.percentile(dev, 99)), "jitter_max": float(dev.max())}
