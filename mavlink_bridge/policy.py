"""What both backends do the same way, over a thin transport a backend gives.

The policy: every vision fix and landing target passes its :class:`OutputGate` (link up,
age, rate), is encoded, written, committed and counted; the EKF origin is repeated until
the autopilot shows it (one message per profile, :func:`origin_message`); an autopilot
reboot forgets the origin, the asked stream intervals and the gates' timing; the needed
streams are asked and watched (:mod:`mavlink_bridge.streams`); the background tasks end
with the bridge. The transport (:class:`~mavlink_bridge.bridge.PymavlinkBridge` on
pymavlink, :class:`~mavlink_bridge.mavsdk_backend.MavsdkBridge` on MAVSDK) says whether the
link is up, writes a vision fix and a message, and posts a message without waiting.
"""

from __future__ import annotations

import asyncio
import contextlib
from abc import ABC, abstractmethod
from collections.abc import Awaitable, Callable, Coroutine
from typing import Any

from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.messages import LandingTargetFix, VisionFix, landing_target_fields
from mavlink_bridge.output import OutputGate, SendResult
from mavlink_bridge.streams import StreamWatch, interval_command, parse_streams
from mavlink_bridge.telemetry import GlobalPosition, Telemetry

MAV_CMD_DO_SET_GLOBAL_ORIGIN = 611
MAV_FRAME_GLOBAL = 0

#: A message: its name, its fields, and the (system, component) it is addressed to.
Message = tuple[str, dict[str, Any], tuple[int, int]]


def origin_seen(item: Telemetry | None) -> bool:
    """True once the autopilot reports an origin (GPS_GLOBAL_ORIGIN, or a non-zero global
    position)."""
    if item is None:
        return False
    if isinstance(item.value, GlobalPosition):
        return item.value.has_origin
    return item.name == "GPS_GLOBAL_ORIGIN"


def origin_message(config: MavlinkConfig, target: int, time_usec: int) -> Message:
    """The EKF origin for the configured profile. ArduPilot: COMMAND_INT 611 (lat/lon degE7,
    alt in metres). PX4: SET_GPS_GLOBAL_ORIGIN (alt in mm), which ArduPilot deprecates but
    PX4 still reads."""
    lat, lon = round(config.origin_lat_deg * 1e7), round(config.origin_lon_deg * 1e7)
    if config.profile == "ardupilot":
        return ("COMMAND_INT", {
            "target_system": target, "target_component": 1, "frame": MAV_FRAME_GLOBAL,
            "command": MAV_CMD_DO_SET_GLOBAL_ORIGIN, "current": 0, "autocontinue": 0,
            "param1": 0.0, "param2": 0.0, "param3": 0.0, "param4": 0.0,
            "x": lat, "y": lon, "z": float(config.origin_alt_m)}, (target, 1))
    return ("SET_GPS_GLOBAL_ORIGIN", {
        "target_system": target, "latitude": lat, "longitude": lon,
        "altitude": round(config.origin_alt_m * 1000), "time_usec": time_usec}, (target, 0))


class BridgePolicy(ABC):
    """The output, origin, reboot and stream policy of a vision bridge (module doc)."""

    def __init__(self, config: MavlinkConfig, clock_ns: Callable[[], int]) -> None:
        config.check()
        self.config = config
        self.clock_ns = clock_ns
        max_age_us = int(config.max_fix_age_ms * 1000)
        self.vision_gate = OutputGate(config.rate_hz, max_age_us)
        self.target_gate = OutputGate(config.landing_target_rate_hz, max_age_us)
        self.origin_attempts = 0
        self._origin_ok = False
        self._tasks: list[asyncio.Task[Any]] = []
        self.streams = StreamWatch(parse_streams(config.streams), self._request_interval,
                                   self.statustext)

    # ------------------------------------------------------------ the transport
    @property
    @abstractmethod
    def link_up(self) -> bool:
        """Whether the autopilot is heard."""

    @abstractmethod
    def target_system(self) -> int:
        """The autopilot's system id, to address commands to."""

    @abstractmethod
    async def _write_vision(self, fix: VisionFix) -> bool:
        """Write one fix as the profile's vision message; False if the backend failed."""

    @abstractmethod
    async def _write(self, message: Message) -> bool:
        """Write one message; False if the backend failed."""

    @abstractmethod
    def _post(self, message: Message) -> None:
        """Send one message without waiting for it (no result)."""

    @abstractmethod
    def statustext(self, text: str, severity: int = 6) -> None:
        """Show a line on the ground station."""

    # ------------------------------------------------------------ output
    async def _gated(self, gate: OutputGate, time_us: int,
                     check: Callable[[int], SendResult | None],
                     write: Callable[[], Awaitable[bool]]) -> SendResult:
        """Link, then ``check(now)``, then ``write()``; commit what was sent; count all."""
        if not self.link_up:
            return gate.count("no_link")
        now = self.clock_ns()
        problem = check(now)
        if problem is not None:
            return gate.count(problem)
        if not await write():
            return gate.count("backend_error")
        gate.commit(time_us)
        return gate.count("sent")

    async def send_fix(self, fix: VisionFix) -> SendResult:
        gate = self.vision_gate
        return await self._gated(gate, fix.time_us, lambda now: gate.check_fix(fix, now),
                                 lambda: self._write_vision(fix))

    async def send_landing_target(self, target: LandingTargetFix) -> SendResult:
        gate = self.target_gate
        fields = landing_target_fields(target, self.config.profile)

        def check(now: int) -> SendResult | None:
            problem = gate.check_target(target, now)
            return problem or (None if fields is not None else "bad_geometry")

        return await self._gated(gate, target.time_us, check, lambda: self._write(
            ("LANDING_TARGET", fields or {}, (0, 0))))

    # ------------------------------------------------------------ EKF origin
    async def send_origin(self) -> None:
        """Send the EKF origin once (counted in ``origin_attempts``)."""
        self.origin_attempts += 1
        await self._write(origin_message(self.config, self.target_system(),
                                         self.clock_ns() // 1000))

    async def _origin_loop(self) -> None:
        """Repeat the origin until the autopilot shows it; ArduPilot SITL answers FAILED
        many times while its EKF is not ready, so failures are never final."""
        while True:
            if self.link_up and not self._origin_ok:
                await self.send_origin()
            await asyncio.sleep(self.config.origin_retry_s)

    def _note_origin(self, item: Telemetry) -> None:
        """Confirm the origin when the autopilot shows one."""
        if not self._origin_ok and origin_seen(item):
            self._origin_ok = True
            self.statustext("EKF origin confirmed")

    @property
    def origin_confirmed(self) -> bool:
        return self._origin_ok

    # ------------------------------------------------------------ reboot and streams
    def _on_reboot(self) -> None:
        """The autopilot rebooted: it lost the origin and every asked interval, and the
        gates' timing refers to its old clock."""
        self._origin_ok = False
        self.vision_gate.reset()
        self.target_gate.reset()
        self.streams.ask_all(self.clock_ns())

    def _request_interval(self, name: str, interval_us: int) -> None:
        target = self.target_system()
        self._post(("COMMAND_LONG", {"target_system": target, "target_component": 1,
                                     "confirmation": 0, **interval_command(name, interval_us)},
                    (target, 1)))

    def stream_report(self) -> dict[str, dict[str, Any]]:
        """Per needed stream: asked rate, measured rate, state (mavlink_bridge.streams)."""
        return self.streams.report(self.clock_ns())

    def stream_warnings(self) -> list[str]:
        """The needed streams that are missing or slow now."""
        return self.streams.missing()

    def _policy_stats(self) -> dict[str, Any]:
        return {"vision": dict(self.vision_gate.counts),
                "landing_target": dict(self.target_gate.counts),
                "origin_attempts": self.origin_attempts, "origin_confirmed": self._origin_ok,
                "streams": self.stream_report()}

    # ------------------------------------------------------------ tasks
    def _spawn(self, coro: Coroutine[Any, Any, Any], name: str | None = None,
               forget: bool = False) -> None:
        """Run ``coro`` as a task the bridge ends on :meth:`_cancel_tasks`; ``forget``
        drops it from the list when it is done (one-shot sends)."""
        task = asyncio.get_running_loop().create_task(coro, name=name)
        self._tasks.append(task)
        if forget:
            task.add_done_callback(self._forget)

    def _forget(self, task: asyncio.Task[Any]) -> None:
        with contextlib.suppress(ValueError):
            self._tasks.remove(task)

    async def _cancel_tasks(self) -> None:
        """Cancel every background task and wait until each has ended."""
        tasks, self._tasks = self._tasks, []
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await t
