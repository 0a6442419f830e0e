"""The second backend: MAVSDK 4.x (native binding, ``mavsdk.asyncio``), same interface.

What MAVSDK does and what we add:

* Connection and HEARTBEAT: MAVSDK, configured as a COMPANION_COMPUTER with our component id
  (HEARTBEAT type ONBOARD_CONTROLLER, autopilot INVALID).  MAVSDK's heartbeat always says
  ``system_status`` 0, so this backend reports the application's health changes by
  STATUSTEXT instead -- use the pymavlink backend when the heartbeat must carry health.
* System id: MAVSDK's is fixed when it is created; with ``system_id = 0`` the backend
  discovers the autopilot's and, if it differs, re-creates MAVSDK with it.
* Vision: the Mocap plugin.  ArduPilot: ODOMETRY with MavFrame.LOCAL_FRD, which MAVSDK sends
  as frame_id 20 / child_frame_id 12 (checked against the fake autopilot), or VPE.  PX4:
  Mocap can only say MOCAP_NED (PX4 does not read it) or LOCAL_FRD (PX4 treats it as an
  unaligned frame), so this backend sends VISION_POSITION_ESTIMATE, which PX4 reads as NED.
* TIMESYNC answers, STATUSTEXT, LANDING_TARGET, the EKF origin and all telemetry go through
  the MavlinkDirect plugin (MAVSDK itself does not answer PX4's TIMESYNC requests).
* The streams the companion needs are asked with SET_MESSAGE_INTERVAL (COMMAND_LONG through
  MavlinkDirect) and watched exactly as in the pymavlink backend (mavlink_bridge.streams).
  MAVSDK's own plugins may ask the autopilot for other rates of the same messages; the last
  request wins on the autopilot, so the watch asks again when a stream slows down.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import time
from collections.abc import AsyncGenerator, Callable
from typing import Any

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
from mavsdk.asyncio.plugins.mocap import MocapAsync
from mavsdk.exceptions import MavsdkError
from mavsdk.plugins.mavlink_direct import MavlinkMessage
from mavsdk.plugins.mocap import (
    AngleBody,
    AngularVelocityBody,
    Covariance,
    Odometry,
    PositionBody,
    Quaternion,
    SpeedBody,
    VisionPositionEstimate,
)

from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.endpoint import Endpoint, parse_endpoint
from mavlink_bridge.errors import BackendError
from mavlink_bridge.link import REBOOT_BACKSTEP_MS, HealthState
from mavlink_bridge.messages import (
    VisionFix,
    odometry_fields,
    vpe_fields,
)
from mavlink_bridge.policy import BridgePolicy, Message
from mavlink_bridge.streams import keep_streams
from mavlink_bridge.telemetry import Telemetry, TelemetryHub, convert

log = logging.getLogger(__name__)
_URL = {"udpin": "udpin", "udpout": "udpout", "tcp": "tcpout", "tcpin": "tcpin"}


def mavsdk_url(ep: Endpoint) -> str:
    """Our endpoint spelling -> MAVSDK's connection URL."""
    if ep.kind == "serial":
        return f"serial://{ep.device}:{ep.baud}"
    return f"{_URL[ep.kind]}://{ep.host}:{ep.port}"


class MavsdkBridge(BridgePolicy):
    """:class:`mavlink_bridge.bridge.VisionBridge` on MAVSDK (see module doc): the transport
    under :class:`~mavlink_bridge.policy.BridgePolicy`."""

    def __init__(self, config: MavlinkConfig, clock_ns: Callable[[], int] = time.monotonic_ns):
        self.system_id = config.system_id or 1
        super().__init__(config, clock_ns)
        self.url = mavsdk_url(parse_endpoint(config.endpoint))
        self.counters: dict[str, int] = {"timesync_answered": 0, "backend_errors": 0,
                                         "queue_drops": 0}
        self._mavsdk: Mavsdk | None = None
        self._direct: MavlinkDirectAsync | None = None
        self._mocap: MocapAsync | None = None
        self._connected = False
        self._health: HealthState = "starting"
        self._last_boot_ms = -1
        self.reboots = 0
        self._hub = TelemetryHub(self.config.rx_queue_len, self.counters)

    # ------------------------------------------------------------ lifecycle
    async def start(self, timeout_s: float = 10.0) -> None:
        """Connect and wait for the autopilot (raises BackendError if none within timeout_s)."""
        system = await self._connect(self.system_id, timeout_s)
        ap_sysid = await system.get_system_id()
        if self.config.system_id == 0 and ap_sysid != self.system_id:
            self._destroy()
            self.system_id = ap_sysid
            system = await self._connect(ap_sysid, timeout_s)
        self._direct = MavlinkDirectAsync(system)
        self._mocap = MocapAsync(system)
        self._connected = True
        self._spawn(self._receive(), "mavsdk-receive")
        self._spawn(self._watch_connection(system), "mavsdk-conn")
        self._spawn(keep_streams(self.streams, lambda: self._connected, self.clock_ns,
                                 self.config.stream_check_s), "mavsdk-streams")
        self.streams.ask_all(self.clock_ns())
        if self.config.set_origin:
            self._spawn(self._origin_loop(), "mavsdk-origin")

    async def _connect(self, sysid: int, timeout_s: float) -> Any:
        cfg = Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER)
        cfg.system_id = sysid
        cfg.component_id = self.config.component_id
        self._mavsdk = Mavsdk(cfg)
        try:
            await self._mavsdk.add_any_connection(self.url)
        except MavsdkError as err:
            raise BackendError(f"mavsdk: cannot open {self.url}: {err}") from err
        system = await self._mavsdk.first_autopilot(timeout_s=timeout_s)
        if system is None:
            self._destroy()
            raise BackendError(f"mavsdk: no autopilot on {self.url} within {timeout_s:.0f} s")
        return system

    def _destroy(self) -> None:
        for plugin in (self._direct, self._mocap):
            if plugin is not None:
                plugin.destroy()
        self._direct = self._mocap = None
        if self._mavsdk is not None:
            self._mavsdk.destroy()
            self._mavsdk = None

    async def stop(self) -> None:
        await self._cancel_tasks()
        self._connected = False
        self._destroy()

    async def __aenter__(self) -> MavsdkBridge:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    async def _watch_connection(self, system: Any) -> None:
        async for connected in system.is_connected_state():
            if connected != self._connected:
                self._connected = bool(connected)
                if connected:
                    self.statustext("link up")
                    self.streams.ask_all(self.clock_ns())

    # ------------------------------------------------------------ the transport
    @property
    def link_up(self) -> bool:
        return self._connected

    def target_system(self) -> int:
        return self.system_id

    async def _write(self, message: Message) -> bool:
        """Send one message through MavlinkDirect; NaN is not valid JSON, so never send it."""
        if self._direct is None:
            return False
        name, fields, target = message
        msg = MavlinkMessage(name, self.system_id, self.config.component_id, target[0],
                             target[1], json.dumps(fields, allow_nan=False))
        try:
            await self._direct.send_message(msg)
        except MavsdkError as err:
            self.counters["backend_errors"] += 1
            log.debug("mavsdk send %s failed: %s", name, err)
            return False
        return True

    def _post(self, message: Message) -> None:
        self._spawn(self._write(message), forget=True)

    async def _write_vision(self, fix: VisionFix) -> bool:
        if self._mocap is None:
            return False
        try:
            if self.config.profile == "ardupilot" and self.config.output == "odometry":
                await self._mocap.set_odometry(_odometry(fix))
            else:
                await self._mocap.set_vision_position_estimate(_vpe(fix))
        except MavsdkError as err:
            log.debug("mavsdk mocap failed: %s", err)
            return False
        return True

    def statustext(self, text: str, severity: int = 6) -> None:
        full = (self.config.statustext_prefix + text)[:50]
        self._post(("STATUSTEXT", {"severity": severity, "text": full}, (0, 0)))

    def report_health(self, state: HealthState) -> None:
        """MAVSDK owns the heartbeat; health changes are announced by STATUSTEXT."""
        if state != self._health:
            if state in ("degraded", "failed") or self._health in ("degraded", "failed"):
                self.statustext(f"health {state}", severity=6 if state == "ok" else 4)
            self._health = state

    # ------------------------------------------------------------ receiving
    async def _receive(self) -> None:
        assert self._direct is not None
        async for msg in self._direct.subscribe_message(""):
            try:
                fields = json.loads(msg.fields_json)
            except ValueError:
                continue
            now = self.clock_ns()
            name = msg.message_name
            if msg.system_id != self.system_id:
                continue
            if name == "TIMESYNC" and int(fields.get("tc1", 1)) == 0:
                # PX4 applies the offset only with round trips < 10 ms: answer at once
                await self._write(("TIMESYNC", {"tc1": now, "ts1": int(fields["ts1"]),
                                                "target_system": msg.system_id,
                                                "target_component": msg.component_id},
                                   (0, 0)))
                self.counters["timesync_answered"] += 1
            self._store(name, msg.system_id, msg.component_id, now, fields)

    def _store(self, name: str, sysid: int, compid: int, now: int,
               fields: dict[str, Any]) -> None:
        self.streams.on_message(name, now)
        if compid == 1 and "time_boot_ms" in fields:
            self._check_reboot(int(fields["time_boot_ms"]))
        value = convert(name, fields)
        if value is None:
            return
        item = Telemetry(name, sysid, compid, now, value)
        self._note_origin(item)
        self._hub.publish(item)

    def _check_reboot(self, boot_ms: int) -> None:
        """time_boot_ms stepping back: the autopilot rebooted and lost its origin."""
        if self._last_boot_ms >= 0 and boot_ms + REBOOT_BACKSTEP_MS < self._last_boot_ms:
            self.reboots += 1
            self.statustext("autopilot reboot detected")
            self._on_reboot()
        self._last_boot_ms = boot_ms

    def latest(self, name: str) -> Telemetry | None:
        return self._hub.latest(name)

    def subscribe(self, *names: str) -> AsyncGenerator[Telemetry, None]:
        """Every new message of the given names; bounded, a slow reader loses the oldest."""
        return self._hub.subscribe(*names)

    async def wait_link(self, up: bool = True, timeout_s: float = 5.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while self._connected != up:
            if time.monotonic() > deadline:
                return False
            await asyncio.sleep(0.02)
        return True

    def stats(self) -> dict[str, Any]:
        return {**self.counters, "link_up": self._connected, "reboots": self.reboots,
                **self._policy_stats()}


def _cov(values: list[float]) -> Covariance:
    return Covariance([v if math.isfinite(v) else math.nan for v in values])


def _odometry(fix: VisionFix) -> Odometry:
    f = odometry_fields(fix, "ardupilot")  # frames 20/12: MAVSDK's LOCAL_FRD
    return Odometry(
        time_usec=fix.time_us, frame_id=Odometry.MavFrame.LOCAL_FRD,
        position_body=PositionBody(f["x"], f["y"], f["z"]), q=Quaternion(*f["q"]),
        speed_body=SpeedBody(f["vx"], f["vy"], f["vz"]),
        angular_velocity_body=AngularVelocityBody(0.0, 0.0, 0.0),
        pose_covariance=_cov(f["pose_covariance"]),
        velocity_covariance=_cov(f["velocity_covariance"]),
        reset_counter=fix.reset_counter & 0xFF,
        estimator_type=Odometry.MavEstimatorType.VISION, quality_percent=f["quality"])


def _vpe(fix: VisionFix) -> VisionPositionEstimate:
    f = vpe_fields(fix)
    return VisionPositionEstimate(
        time_usec=fix.time_us, position_body=PositionBody(f["x"], f["y"], f["z"]),
        angle_body=AngleBody(f["roll"], f["pitch"], f["yaw"]),
        pose_covariance=_cov(f["covariance"]), reset_counter=f["reset_counter"])
