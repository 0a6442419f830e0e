"""The vision bridge on pymavlink: link + per-profile vision output + EKF origin.

:class:`VisionBridge` is the interface both backends implement (this one and
:mod:`mavlink_bridge.mavsdk_backend`); :func:`create_bridge` picks one from the config.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncGenerator, Callable
from typing import Any, Protocol

from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.errors import BackendError
from mavlink_bridge.link import HealthState, MavlinkLink
from mavlink_bridge.messages import (
    LandingTargetFix,
    VisionFix,
    landing_target_fields,
    odometry_fields,
    vpe_fields,
)
from mavlink_bridge.output import OutputGate, SendResult
from mavlink_bridge.streams import StreamWatch, interval_command, keep_streams, parse_streams
from mavlink_bridge.telemetry import GlobalPosition, Telemetry

MAV_CMD_DO_SET_GLOBAL_ORIGIN = 611
MAV_FRAME_GLOBAL = 0


class VisionBridge(Protocol):
    """What the application uses, whichever backend is configured."""

    config: MavlinkConfig

    async def start(self) -> None: ...
    async def stop(self) -> None: ...
    def report_health(self, state: HealthState) -> None: ...
    async def send_fix(self, fix: VisionFix) -> SendResult: ...
    async def send_landing_target(self, target: LandingTargetFix) -> SendResult: ...
    def statustext(self, text: str, severity: int = 6) -> None: ...
    def latest(self, name: str) -> Telemetry | None: ...
    def subscribe(self, *names: str) -> AsyncGenerator[Telemetry, None]: ...
    @property
    def link_up(self) -> bool: ...
    @property
    def origin_confirmed(self) -> bool: ...
    async def wait_link(self, up: bool = True, timeout_s: float = 5.0) -> bool: ...
    def stats(self) -> dict[str, Any]: ...
    def stream_report(self) -> dict[str, dict[str, Any]]: ...
    def stream_warnings(self) -> list[str]: ...


def origin_seen(item: Telemetry | None) -> bool:
    """True when a GLOBAL_POSITION_INT shows a position (so the origin is set) or a
    GPS_GLOBAL_ORIGIN came back."""
    if item is None:
        return False
    if isinstance(item.value, GlobalPosition):
        return item.value.has_origin
    return item.name == "GPS_GLOBAL_ORIGIN"


class PymavlinkBridge:
    """The default backend.  ``async with PymavlinkBridge(cfg) as b: await b.send_fix(fix)``."""

    def __init__(self, config: MavlinkConfig, clock_ns: Callable[[], int] = time.monotonic_ns):
        config.check()
        self.config = config
        self.clock_ns = clock_ns
        self.link = MavlinkLink(config, clock_ns)
        max_age_us = int(config.max_fix_age_ms * 1000)
        self.vision_gate = OutputGate(config.rate_hz, max_age_us)
        self.target_gate = OutputGate(config.landing_target_rate_hz, max_age_us)
        self.origin_attempts = 0
        self._origin_ok = False
        self._tasks: list[asyncio.Task[None]] = []
        self.link.reboot_listeners.append(self._on_reboot)
        self.streams = StreamWatch(parse_streams(config.streams), self._request_interval,
                                   self.link.statustext)
        self.link.rx_listeners.append(self.streams.on_message)
        self.link.link_listeners.append(self._on_link)

    async def start(self) -> None:
        await self.link.start()
        self._tasks = [asyncio.create_task(self._watch_origin(), name="mavlink-origin-watch"),
                       asyncio.create_task(keep_streams(
                           self.streams, lambda: self.link.link_up, self.clock_ns,
                           self.config.stream_check_s), name="mavlink-streams")]
        if self.config.set_origin:
            self._tasks.append(asyncio.create_task(self._origin_loop(), name="mavlink-origin"))

    async def stop(self) -> None:
        for t in self._tasks:
            t.cancel()
        for t in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await t
        self._tasks = []
        await self.link.stop()

    async def __aenter__(self) -> PymavlinkBridge:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    # ------------------------------------------------------------ pass-through
    def report_health(self, state: HealthState) -> None:
        self.link.report_health(state)

    def statustext(self, text: str, severity: int = 6) -> None:
        self.link.statustext(text, severity)

    def latest(self, name: str) -> Telemetry | None:
        return self.link.latest(name)

    def subscribe(self, *names: str) -> AsyncGenerator[Telemetry, None]:
        return self.link.subscribe(*names)

    @property
    def link_up(self) -> bool:
        return self.link.link_up

    @property
    def origin_confirmed(self) -> bool:
        return self._origin_ok

    async def wait_link(self, up: bool = True, timeout_s: float = 5.0) -> bool:
        return await self.link.wait_link(up, timeout_s)

    def stats(self) -> dict[str, Any]:
        out = self.link.stats()
        out["vision"] = dict(self.vision_gate.counts)
        out["landing_target"] = dict(self.target_gate.counts)
        out["origin_attempts"] = self.origin_attempts
        out["origin_confirmed"] = self._origin_ok
        out["streams"] = self.stream_report()
        return out

    # ------------------------------------------------------------ streams
    def stream_report(self) -> dict[str, dict[str, Any]]:
        """Per needed stream: asked rate, measured rate, state (mavlink_bridge.streams)."""
        return self.streams.report(self.clock_ns())

    def stream_warnings(self) -> list[str]:
        """The needed streams that are missing or slow now."""
        return self.streams.missing()

    def _request_interval(self, name: str, interval_us: int) -> None:
        target = self.link.autopilot_sysid or 1
        self.link.send("COMMAND_LONG", target_system=target, target_component=1,
                       confirmation=0, **interval_command(name, interval_us))

    def _on_link(self, up: bool) -> None:
        if up:
            self.streams.ask_all(self.clock_ns())

    # ------------------------------------------------------------ vision output
    def send_fix_now(self, fix: VisionFix) -> SendResult:
        """Check and send one fix synchronously (no await: a socket write)."""
        gate = self.vision_gate
        if not self.link.link_up:
            return gate.count("no_link")
        now = self.clock_ns()
        problem = gate.check_fix(fix, now)
        if problem is not None:
            return gate.count(problem)
        if self.config.output == "vpe":
            self.link.send("VISION_POSITION_ESTIMATE", **vpe_fields(fix))
        else:
            self.link.send("ODOMETRY", **odometry_fields(fix, self.config.profile))
        gate.commit(fix.time_us, now)
        return gate.count("sent")

    async def send_fix(self, fix: VisionFix) -> SendResult:
        return self.send_fix_now(fix)

    async def send_landing_target(self, target: LandingTargetFix) -> SendResult:
        gate = self.target_gate
        if not self.link.link_up:
            return gate.count("no_link")
        now = self.clock_ns()
        problem = gate.check_target(target, now)
        if problem is not None:
            return gate.count(problem)
        fields = landing_target_fields(target, self.config.profile)
        if fields is None:
            return gate.count("bad_geometry")
        self.link.send("LANDING_TARGET", **fields)
        gate.commit(target.time_us, now)
        return gate.count("sent")

    # ------------------------------------------------------------ EKF origin
    def send_origin(self) -> None:
        """ArduPilot: COMMAND_INT 611 (lat/lon degE7, alt in metres).  PX4: SET_GPS_GLOBAL_ORIGIN
        (alt in mm), which ArduPilot deprecates but PX4 still reads."""
        c = self.config
        target = self.link.autopilot_sysid or 1
        lat, lon = round(c.origin_lat_deg * 1e7), round(c.origin_lon_deg * 1e7)
        if c.profile == "ardupilot":
            self.link.send("COMMAND_INT", target_system=target, target_component=1,
                           frame=MAV_FRAME_GLOBAL, command=MAV_CMD_DO_SET_GLOBAL_ORIGIN,
                           current=0, autocontinue=0, param1=0.0, param2=0.0, param3=0.0,
                           param4=0.0, x=lat, y=lon, z=float(c.origin_alt_m))
        else:
            self.link.send("SET_GPS_GLOBAL_ORIGIN", target_system=target, latitude=lat,
                           longitude=lon, altitude=round(c.origin_alt_m * 1000),
                           time_usec=self.clock_ns() // 1000)
        self.origin_attempts += 1

    async def _origin_loop(self) -> None:
        """Repeat the origin until the autopilot shows it; ArduPilot SITL answers FAILED
        many times while its EKF is not ready, so failures are never final."""
        while True:
            if self.link.link_up and not self._origin_ok:
                self.send_origin()
            await asyncio.sleep(self.config.origin_retry_s)

    async def _watch_origin(self) -> None:
        async for item in self.link.subscribe("GLOBAL_POSITION_INT", "GPS_GLOBAL_ORIGIN"):
            if not self._origin_ok and origin_seen(item):
                self._origin_ok = True
                self.link.statustext("EKF origin confirmed")

    def _on_reboot(self) -> None:
        self._origin_ok = False
        self.streams.ask_all(self.clock_ns())  # a reboot forgets every interval
        self.vision_gate.reset()
        self.target_gate.reset()


def create_bridge(config: MavlinkConfig) -> VisionBridge:
    """The backend the configuration asks for."""
    if config.backend == "mavsdk":
        try:  # native library: load lazily
            from mavlink_bridge.mavsdk_backend import MavsdkBridge
        except ImportError as err:
            raise BackendError(
                f"mavlink.backend = \"mavsdk\" needs the optional package mavsdk ({err.name} "
                "is not installed): pip install 'landmark-companion[mavsdk]'") from None

        return MavsdkBridge(config)
    return PymavlinkBridge(config)
