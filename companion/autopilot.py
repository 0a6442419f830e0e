"""The application's side of the MAVLink bridge: fixes out, attitude in, health to heartbeat.

``tracker`` and ``mavlink_bridge`` do not know each other; this module converts a
:class:`tracker.pose.types.PoseFix` into the bridge's :class:`VisionFix`, decides when a
fix is a deliberate jump (``reset_counter``), and turns the autopilot's telemetry into the
side samples the pose solver uses.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.pipeline.health import State
from mavlink_bridge.bridge import VisionBridge
from mavlink_bridge.link import HealthState
from mavlink_bridge.messages import VisionFix
from tracker.pose.types import AttitudeSample, PoseFix

log = logging.getLogger(__name__)

#: A fix after this long without one, and this many sigmas away, is a re-localisation.
RESET_GAP_S = 1.0
RESET_SIGMAS = 5.0
#: The pipeline's state as the heartbeat's health (MAV_STATE via the link).
HEARTBEAT_HEALTH: dict[State, HealthState] = {
    "starting": "starting", "searching": "ok", "tracking": "ok", "lost": "degraded",
    "degraded": "degraded", "link-down": "ok",
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
            if state in ("tracking", "lost", "degraded"):
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


class AttitudeHistory:
    """The autopilot's recent ATTITUDE messages, to look up the attitude at a frame's time.

    A frame is solved some milliseconds after it was captured; the attitude that belongs
    to it is the one of its capture time, interpolated between the two nearest samples
    (stamped with their arrival on the companion's clock).
    """

    def __init__(self, bridge: VisionBridge, keep: int = 200) -> None:
        self.bridge = bridge
        self._samples: deque[tuple[int, float, float, float]] = deque(maxlen=keep)
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        """Follow the bridge's ATTITUDE stream until :meth:`stop`."""
        self._task = asyncio.create_task(self._follow(), name="attitude-history")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)

    async def _follow(self) -> None:
        async for item in self.bridge.subscribe("ATTITUDE"):
            v = item.value
            self._samples.append((item.received_ns // 1000, float(v.roll_rad),
                                  float(v.pitch_rad), float(v.yaw_rad)))

    def at(self, t_us: int, max_gap_us: int = 100_000) -> AttitudeSample | None:
        """The attitude at ``t_us`` (interpolated; yaw the short way round), or None."""
        samples = list(self._samples)  # a copy: the event loop appends while we read
        if not samples:
            return None
        after = next((i for i, s in enumerate(samples) if s[0] >= t_us), None)
        if after is None or after == 0:
            near = samples[-1] if after is None else samples[0]
            if abs(near[0] - t_us) > max_gap_us:
                return None
            return AttitudeSample(t_us, near[1], near[2], near[3])
        a, b = samples[after - 1], samples[after]
        f = (t_us - a[0]) / max(b[0] - a[0], 1)
        dyaw = math.remainder(b[3] - a[3], math.tau)
        return AttitudeSample(t_us, a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]),
                              math.remainder(a[3] + f * dyaw, math.tau))
