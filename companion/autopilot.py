"""The application's side of the MAVLink bridge: fixes out, attitude in, health to heartbeat.

``tracker`` and ``mavlink_bridge`` do not know each other; this module converts a
:class:`tracker.pose.types.PoseFix` into the bridge's :class:`VisionFix`, decides when a
fix is a deliberate jump (``reset_counter``), and follows the pipeline's health.  The
autopilot's side sensors for the pose solver: :mod:`companion.sensors`.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.pipeline.health import State
from mavlink_bridge.bridge import VisionBridge
from mavlink_bridge.link import HealthState
from mavlink_bridge.messages import VisionFix
from tracker.pose.types import PoseFix

log = logging.getLogger(__name__)

#: A fix after this long without one, and this many sigmas away, is a re-localisation.
RESET_GAP_S = 1.0
RESET_SIGMAS = 5.0
#: The pipeline's state as the heartbeat's health (MAV_STATE via the link).
HEARTBEAT_HEALTH: dict[State, HealthState] = {
    "starting": "starting", "searching": "ok", "tracking": "ok", "lost": "degraded",
    "degraded": "degraded", "link-down": "ok", "blocked": "degraded",
}


def vision_fix(fix: PoseFix, reset_counter: int) -> VisionFix:
    """The bridge's input for a pose fix (covariance as the 6x6 matrix, quality 0..100):
    the position and covariance the fix gate stated for the autopilot when it stated them
    (``PoseFix.sent_position_ned_m`` / ``sent_covariance``, docs/decisions.md "Fixes that
    echo the autopilot's own error", "A fix ArduPilot cannot weigh is sent as its pull"),
    else the fix's own."""
    cov = np.asarray(fix.autopilot_covariance, dtype=np.float64)
    return VisionFix(
        time_us=int(fix.time_us),
        position_ned_m=tuple(float(v) for v in fix.autopilot_position),  # type: ignore[arg-type]
        attitude_rpy_rad=tuple(float(v) for v in fix.attitude_rpy_rad),  # type: ignore[arg-type]
        covariance=tuple(float(v) for v in cov[np.triu_indices(6)]),
        quality_percent=int(max(0, min(100, fix.quality))),
        reset_counter=reset_counter % 256,
    )


@dataclass
class ResetPolicy:
    """Bumps ``reset_counter`` when a fix jumps after a gap (a re-localisation).

    :meth:`counter_for` says what a fix would carry; only :meth:`commit` of a fix that was
    sent advances anything: a refused fix is no re-localisation the autopilot saw."""

    counter: int = 0
    last_time_us: int | None = None
    last_position: tuple[float, float, float] | None = None

    def counter_for(self, fix: PoseFix) -> int:
        """The ``reset_counter`` ``fix`` carries if it is sent."""
        if self.last_time_us is None or self.last_position is None:
            return self.counter
        gap_s = (fix.time_us - self.last_time_us) / 1e6
        jump = math.dist(fix.position_ned_m, self.last_position)
        sigma = max(float(np.sqrt(np.trace(np.asarray(fix.covariance)[:3, :3]))), 0.01)
        return self.counter + 1 if gap_s > RESET_GAP_S and jump > RESET_SIGMAS * sigma \
            else self.counter

    def commit(self, fix: PoseFix, counter: int) -> None:
        """``fix`` was sent with ``counter``."""
        if counter != self.counter and self.last_position is not None:
            log.info("re-localised: %.2f m jump; reset_counter %d",
                     math.dist(fix.position_ned_m, self.last_position), counter)
        self.counter = counter
        self.last_time_us, self.last_position = fix.time_us, fix.position_ned_m


#: A refusal's log line repeats at most this often per reason (the count in between).
REFUSAL_LOG_S = 5.0
#: Refusals that are the output's pacing (mavlink.rate_hz, EKF3's 20 ms spacing), not a
#: fault: logged at INFO, the others at WARNING.
PACING = ("rate_limited", "not_newer")


class RefusalLog:
    """Logs refused fixes with their reason, at most once per :data:`REFUSAL_LOG_S` per
    reason, saying how many were refused in between."""

    def __init__(self, clock_s: Callable[[], float] = time.monotonic) -> None:
        self.clock_s = clock_s
        self._last: dict[str, float] = {}
        self._since: dict[str, int] = {}

    def note(self, reason: str) -> None:
        now = self.clock_s()
        self._since[reason] = self._since.get(reason, 0) + 1
        last = self._last.get(reason)
        if last is None or now - last >= REFUSAL_LOG_S:
            level = logging.INFO if reason in PACING else logging.WARNING
            log.log(level, "fix not sent: %s (%d such since the last line; docs/replay.md)",
                    reason, self._since[reason])
            self._last[reason], self._since[reason] = now, 0


def outcome_lines(results: dict[str, int]) -> tuple[str, str | None]:
    """The end of a flight: fixes sent and refused by reason, and a warning when fixes
    were solved but none was sent (with the top reason)."""
    refused = {k: v for k, v in results.items() if k != "sent"}
    sent = results.get("sent", 0)
    by_reason = ", ".join(f"{k} {v}" for k, v in sorted(refused.items(), key=lambda kv: -kv[1]))
    line = f"{sent} fixes sent, {sum(refused.values())} refused" + \
        (f" ({by_reason})" if by_reason else "")
    warning = None
    if sent == 0 and refused:
        top = max(refused.items(), key=lambda kv: kv[1])
        warning = (f"no fix was sent although {sum(refused.values())} were solved: "
                   f"mostly {top[0]} ({top[1]})")
    return line, warning


class BridgeSink:
    """:class:`companion.app.FixSink` over a running :class:`VisionBridge`."""

    def __init__(self, bridge: VisionBridge) -> None:
        self.bridge = bridge
        self.reset = ResetPolicy()
        self.results: dict[str, int] = {}
        self.last_result: str | None = None
        self.refusals = RefusalLog()
        self._last_state: State | None = None

    @property
    def link_up(self) -> bool:
        return bool(self.bridge.link_up)

    def set_health(self, state: State) -> None:
        """Called on every frame and status tick: the heartbeat follows the pipeline."""
        self.bridge.report_health(HEARTBEAT_HEALTH[state])
        if state != self._last_state:
            self._last_state = state
            if state in ("tracking", "lost", "degraded", "blocked"):
                self.bridge.statustext(state)

    async def send_fix(self, fix: Any) -> bool:
        """Send ``fix``; a refused one advances nothing (reset counter, last fix) and is
        logged (:class:`RefusalLog`); its reason stays in :attr:`last_result`."""
        counter = self.reset.counter_for(fix)
        result = await self.bridge.send_fix(vision_fix(fix, counter))
        self.results[result] = self.results.get(result, 0) + 1
        self.last_result = result
        if result == "sent":
            self.reset.commit(fix, counter)
        else:
            self.refusals.note(result)
        return result == "sent"

    async def statustext(self, text: str) -> None:
        self.bridge.statustext(text)

    def autopilot_streams(self) -> dict[str, Any]:
        """Per needed stream from the autopilot: asked rate, measured rate, state."""
        return self.bridge.stream_report()

    def warnings(self) -> list[str]:
        """Health warnings: each needed autopilot stream that is missing or slow."""
        return [f"autopilot stream {name} not arriving" for name in self.bridge.stream_warnings()]

    def autopilot_position_ned(self) -> list[float] | None:
        """The autopilot's own estimate (LOCAL_POSITION_NED), for plots; None if unknown."""
        item = self.bridge.latest("LOCAL_POSITION_NED")
        if item is None:
            return None
        v = item.value
        return [round(float(v.north_m), 3), round(float(v.east_m), 3), round(float(v.down_m), 3)]
