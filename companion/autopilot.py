"""The application's side of the MAVLink bridge: fixes out, attitude in, health to heartbeat.

``tracker`` and ``mavlink_bridge`` do not know each other; this module converts a
:class:`tracker.pose.types.PoseFix` into the bridge's :class:`VisionFix`, decides when a
fix is a deliberate jump (``reset_counter``), and follows the pipeline's health.  The
autopilot's side sensors for the pose solver: :mod:`companion.sensors`.
"""

from __future__ import annotations

import logging
import math
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
    """The bridge's input for a pose fix (covariance as the 6x6 matrix, quality 0..100)."""
    cov = np.asarray(fix.covariance, dtype=np.float64)
    return VisionFix(
        time_us=int(fix.time_us),
        position_ned_m=tuple(float(v) for v in fix.position_ned_m),  # type: ignore[arg-type]
        attitude_rpy_rad=tuple(float(v) for v in fix.attitude_rpy_rad),  # type: ignore[arg-type]
        covariance=tuple(float(v) for v in cov[np.triu_indices(6)]),
        quality_percent=int(max(0, min(100, fix.quality))),
        reset_counter=reset_counter % 256,
    )


@dataclass
class ResetPolicy:
    """Bumps ``reset_counter`` when a fix jumps after a gap (a re-localisation)."""

    counter: int = 0
    last_time_us: int | None = None
    last_position: tuple[float, float, float] | None = None

    def update(self, fix: PoseFix) -> int:
        if self.last_time_us is not None and self.last_position is not None:
            gap_s = (fix.time_us - self.last_time_us) / 1e6
            jump = math.dist(fix.position_ned_m, self.last_position)
            sigma = max(float(np.sqrt(np.trace(np.asarray(fix.covariance)[:3, :3]))), 0.01)
            if gap_s > RESET_GAP_S and jump > RESET_SIGMAS * sigma:
                self.counter += 1
                log.info("re-localised: %.2f m jump after %.1f s; reset_counter %d",
                         jump, gap_s, self.counter)
        self.last_time_us, self.last_position = fix.time_us, fix.position_ned_m
        return self.counter


class BridgeSink:
    """:class:`companion.app.FixSink` over a running :class:`VisionBridge`."""

    def __init__(self, bridge: VisionBridge) -> None:
        self.bridge = bridge
        self.reset = ResetPolicy()
        self.results: dict[str, int] = {}
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
        result = await self.bridge.send_fix(vision_fix(fix, self.reset.update(fix)))
        self.results[result] = self.results.get(result, 0) + 1
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
