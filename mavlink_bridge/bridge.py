"""The vision bridge on pymavlink: link + per-profile vision output + EKF origin.

:class:`VisionBridge` is the interface both backends implement (this one and
:mod:`mavlink_bridge.mavsdk_backend`); :func:`create_bridge` picks one from the config. Their
common policy (gates, origin, reboot, streams, tasks) is :class:`~mavlink_bridge.policy.
BridgePolicy`; this module is its transport over :class:`~mavlink_bridge.link.MavlinkLink`.
"""

from __future__ import annotations

import time
from collections.abc import AsyncGenerator, Callable
from typing import Any, Protocol

from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.errors import BackendError
from mavlink_bridge.link import HealthState, MavlinkLink
from mavlink_bridge.messages import (
    LandingTargetFix,
    VisionFix,
    odometry_fields,
    vpe_fields,
)
from mavlink_bridge.output import SendResult
from mavlink_bridge.policy import (
    MAV_CMD_DO_SET_GLOBAL_ORIGIN,
    MAV_FRAME_GLOBAL,
    BridgePolicy,
    Message,
    origin_seen,
)
from mavlink_bridge.streams import keep_streams
from mavlink_bridge.telemetry import Telemetry

__all__ = ["MAV_CMD_DO_SET_GLOBAL_ORIGIN", "MAV_FRAME_GLOBAL", "PymavlinkBridge",
           "VisionBridge", "create_bridge", "origin_seen"]


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


class PymavlinkBridge(BridgePolicy):
    """The default backend.  ``async with PymavlinkBridge(cfg) as b: await b.send_fix(fix)``."""

    def __init__(self, config: MavlinkConfig, clock_ns: Callable[[], int] = time.monotonic_ns):
        super().__init__(config, clock_ns)
        self.link = MavlinkLink(config, clock_ns)
        self.link.reboot_listeners.append(self._on_reboot)
        self.link.rx_listeners.append(self.streams.on_message)
        self.link.link_listeners.append(self._on_link)

    async def start(self) -> None:
        await self.link.start()
        self._spawn(self._watch_origin(), "mavlink-origin-watch")
        self._spawn(keep_streams(self.streams, lambda: self.link.link_up, self.clock_ns,
                                 self.config.stream_check_s), "mavlink-streams")
        if self.config.set_origin:
            self._spawn(self._origin_loop(), "mavlink-origin")

    async def stop(self) -> None:
        await self._cancel_tasks()
        await self.link.stop()

    async def __aenter__(self) -> PymavlinkBridge:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    # ------------------------------------------------------------ the transport
    @property
    def link_up(self) -> bool:
        return self.link.link_up

    def target_system(self) -> int:
        return self.link.autopilot_sysid or 1

    async def _write_vision(self, fix: VisionFix) -> bool:
        if self.config.output == "vpe":
            self.link.send("VISION_POSITION_ESTIMATE", **vpe_fields(fix))
        else:
            self.link.send("ODOMETRY", **odometry_fields(fix, self.config.profile))
        return True

    async def _write(self, message: Message) -> bool:
        self._post(message)
        return True

    def _post(self, message: Message) -> None:
        name, fields, _ = message  # the link addresses by the fields' target_system
        self.link.send(name, **fields)

    def statustext(self, text: str, severity: int = 6) -> None:
        self.link.statustext(text, severity)

    # ------------------------------------------------------------ pass-through
    def report_health(self, state: HealthState) -> None:
        self.link.report_health(state)

    def latest(self, name: str) -> Telemetry | None:
        return self.link.latest(name)

    def subscribe(self, *names: str) -> AsyncGenerator[Telemetry, None]:
        return self.link.subscribe(*names)

    async def wait_link(self, up: bool = True, timeout_s: float = 5.0) -> bool:
        return await self.link.wait_link(up, timeout_s)

    def stats(self) -> dict[str, Any]:
        return {**self.link.stats(), **self._policy_stats()}

    def _on_link(self, up: bool) -> None:
        if up:
            self.streams.ask_all(self.clock_ns())

    async def _watch_origin(self) -> None:
        async for item in self.link.subscribe("GLOBAL_POSITION_INT", "GPS_GLOBAL_ORIGIN"):
            self._note_origin(item)


def create_bridge(config: MavlinkConfig,
                  clock_ns: Callable[[], int] | None = None) -> VisionBridge:
    """The backend the configuration asks for; ``clock_ns``: the clock the bridge judges
    ages and stamps arrivals with, when not the machine's monotonic one (a replay on the
    recording's clock, pymavlink only: MAVSDK keeps its own)."""
    if config.backend == "mavsdk":
        try:  # native library: load lazily
            from mavlink_bridge.mavsdk_backend import MavsdkBridge
        except ImportError as err:
            raise BackendError(
                f"mavlink.backend = \"mavsdk\" needs the optional package mavsdk ({err.name} "
                "is not installed): pip install 'landmark-companion[mavsdk]'") from None

        if clock_ns is not None:
            raise BackendError("mavlink.backend = \"mavsdk\" keeps its own clock: a replay "
                               "on the recording's clock (--fast) needs \"pymavlink\"")
        return MavsdkBridge(config)
    return PymavlinkBridge(config, clock_ns or time.monotonic_ns)
