"""Rules every vision output obeys, whatever the backend: fresh, finite, rate-limited.

:class:`OutputGate` decides whether a fix may go out now; it is pure bookkeeping (no I/O), so
both backends share it and tests can drive it with a fake clock.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from mavlink_bridge.messages import LandingTargetFix, VisionFix, fix_problem

SendResult = Literal[
    "sent", "rate_limited", "not_newer", "stale", "future", "non_finite", "bad_covariance",
    "bad_quality", "bad_geometry", "no_link", "backend_error",
]
# EKF3 discards external-nav samples less than 20 ms apart (MAVLINK.md, "Rate and health").
MIN_SAMPLE_SPACING_US = 20_000


@dataclass
class OutputGate:
    """Admission control for one output stream.

    A fix passes when it is finite, not older than ``max_age_us``, and its sample time is
    newer than the last one sent by at least ``MIN_SAMPLE_SPACING_US`` and ``0.9 / rate_hz``
    (10 % slack so a 30 Hz camera is not halved).  Sample time, not send time: the autopilot
    spaces and fuses the samples by their stamps (EKF3 by the stamp plus its jitter
    correction, MAVLINK.md "Time"), so two fixes of frames 33 ms apart that leave 20 ms apart
    because the first took longer are both fused.  The send-time rule this replaces refused
    14-18 % of a 30 Hz camera's fixes for the processing's jitter alone (issue 23's trace;
    docs/decisions.md, "The output rate is the samples' rate").
    """

    rate_hz: float
    max_age_us: int
    counts: dict[str, int] = field(default_factory=dict)
    last_sample_us: int | None = None

    def check_fix(self, fix: VisionFix, now_ns: int) -> SendResult | None:
        problem = fix_problem(fix, now_ns // 1000, self.max_age_us)
        if problem is not None:
            return problem  # type: ignore[return-value]
        return self._check_timing(fix.time_us)

    def check_target(self, lt: LandingTargetFix, now_ns: int) -> SendResult | None:
        age_us = now_ns // 1000 - lt.time_us
        if age_us > self.max_age_us:
            return "stale"
        if age_us < -self.max_age_us:
            return "future"
        return self._check_timing(lt.time_us)

    def _check_timing(self, sample_us: int) -> SendResult | None:
        if self.last_sample_us is not None:
            spacing = max(MIN_SAMPLE_SPACING_US, 0.9e6 / self.rate_hz)
            if sample_us - self.last_sample_us < spacing:
                return "not_newer" if sample_us <= self.last_sample_us else "rate_limited"
        return None

    def commit(self, sample_us: int) -> None:
        self.last_sample_us = sample_us

    def count(self, result: SendResult) -> SendResult:
        self.counts[result] = self.counts.get(result, 0) + 1
        return result

    def reset(self) -> None:
        """Forget the last sample (after an autopilot reboot its clock started again)."""
        self.last_sample_us = None
