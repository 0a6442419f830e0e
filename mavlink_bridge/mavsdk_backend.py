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
import contextlib
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

from mavlink_bridge.bridge import MAV_CMD_DO_SET_GLOBAL_ORIGIN, origin_seen
from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.endpoint import Endpoint, parse_endpoint
from mavlink_bridge.errors import BackendError
from mavlink_bridge.link import REBOOT_BACKSTEP_MS, HealthState
from mavlink_bridge.messages import (
    LandingTargetFix,
    VisionFix,
    landing_target_fields,
    odometry_fields,
    vpe_fields,
)
from mavlink_bridge.output import OutputGate, SendResult
from mavlink_bridge.streams import StreamWatch, interval_command, keep_streams, parse_streams
from mavlink_bridge.telemetry import Telemetry, TelemetryHub, convert

log = logging.getLogger(__name__)
_URL = {"udpin": "udpin", "udpout": "udpout", "tcp": "tcpout", "tcpin": "tcpin"}


def mavsdk_url(ep: Endpoint) -> str:
    """Our endpoint spelling -> MAVSDK's connection URL."""
    if ep.kind == "serial":
        return f"serial://{ep.device}:{ep.baud}"
    return f"{_URL[ep.kind]}://{ep.host}:{ep.port}"


class MavsdkBridge:
    """:class:`mavlink_bridge.bridge.VisionBridge` on MAVSDK (see module doc)."""

    def __init__(self, config: MavlinkConfig, clock_ns: Callable[[], int] = time.monotonic_ns):
        config.check()
        self.config = config
        self.clock_ns = clock_ns
        self.url = mavsdk_url(parse_endpoint(config.endpoint))
        max_age_us = int(config.max_fix_age_ms * 1000)
        self.vision_gate = OutputGate(config.rate_hz, max_age_us)
        self.target_gate = OutputGate(config.landing_target_rate_hz, max_age_us)
        self.counters: dict[str, int] = {"timesync_answered": 0, "backend_errors": 0,
                                         "queue_drops": 0, "origin_attempts": 0}
        self.system_id = config.system_id or 1
        self._mavsdk: Mavsdk | None = None
        self._direct: MavlinkDirectAsync | None = None
        self._mocap: MocapAsync | None = None
        self._connected = False
        self._origin_ok = False
        self._health: HealthState = "starting"
        self._last_boot_ms = -1
        self.reboots = 0
        self._hub = TelemetryHub(self.config.rx_queue_len, self.counters)
        self._tasks: list[asyncio.Task[Any]] = []
        self.streams = StreamWatch(parse_streams(config.streams), self._request_interval,
                                   self.statustext)

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
        self._tasks = [asyncio.create_task(self._receive(), name="mavsdk-receive"),
                       asyncio.create_task(self._watch_connection(system), name="mavsdk-conn"),
                       asyncio.create_task(keep_streams(
                           self.streams, lambda: self._connected, self.clock_ns,
                           self.config.stream_check_s), name="mavsdk-streams")]
        self.streams.ask_all(self.clock_ns())
        if self.config.set_origin:
            self._tasks.append(asyncio.create_task(self._origin_loop(), name="mavsdk-origin"))

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
        for t in self._tasks:
            t.cancel()
        for t in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await t
        self._tasks = []
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

    # ------------------------------------------------------------ sending
    async def _send(self, name: str, fields: dict[str, Any],
                    target: tuple[int, int] = (0, 0)) -> bool:
        """Send one message through MavlinkDirect; NaN is not valid JSON, so never send it."""
        if self._direct is None:
            return False
        msg = MavlinkMessage(name, self.system_id, self.config.component_id, target[0],
                             target[1], json.dumps(fields, allow_nan=False))
        try:
            await self._direct.send_message(msg)
        except MavsdkError as err:
            self.counters["backend_errors"] += 1
            log.debug("mavsdk send %s failed: %s", name, err)
            return False
        return True

    def _request_interval(self, name: str, interval_us: int) -> None:
        fields: dict[str, Any] = {"target_system": self.system_id, "target_component": 1,
                                  "confirmation": 0, **interval_command(name, interval_us)}
        task = asyncio.get_running_loop().create_task(
            self._send("COMMAND_LONG", fields, (self.system_id, 1)))
        self._tasks.append(task)
        task.add_done_callback(self._forget)

    def statustext(self, text: str, severity: int = 6) -> None:
        full = (self.config.statustext_prefix + text)[:50]
        task = asyncio.get_running_loop().create_task(
            self._send("STATUSTEXT", {"severity": severity, "text": full}))
        self._tasks.append(task)
        task.add_done_callback(self._forget)

    def _forget(self, task: asyncio.Task[Any]) -> None:
        with contextlib.suppress(ValueError):
            self._tasks.remove(task)

    def report_health(self, state: HealthState) -> None:
        """MAVSDK owns the heartbeat; health changes are announced by STATUSTEXT."""
        if state != self._health:
            if state in ("degraded", "failed") or self._health in ("degraded", "failed"):
                self.statustext(f"health {state}", severity=6 if state == "ok" else 4)
            self._health = state

    async def send_fix(self, fix: VisionFix) -> SendResult:
        gate = self.vision_gate
        if not self._connected or self._mocap is None:
            return gate.count("no_link")
        now = self.clock_ns()
        problem = gate.check_fix(fix, now)
        if problem is not None:
            return gate.count(problem)
        try:
            if self.config.profile == "ardupilot" and self.config.output == "odometry":
                await self._mocap.set_odometry(_odometry(fix))
            else:
                await self._mocap.set_vision_position_estimate(_vpe(fix))
        except MavsdkError as err:
            log.debug("mavsdk mocap failed: %s", err)
            return gate.count("backend_error")
        gate.commit(fix.time_us, now)
        return gate.count("sent")

    async def send_landing_target(self, target: LandingTargetFix) -> SendResult:
        gate = self.target_gate
        if not self._connected:
            return gate.count("no_link")
        now = self.clock_ns()
        problem = gate.check_target(target, now)
        if problem is not None:
            return gate.count(problem)
        fields = landing_target_fields(target, self.config.profile)
        if fields is None:
            return gate.count("bad_geometry")
        if not await self._send("LANDING_TARGET", fields):
            return gate.count("backend_error")
        gate.commit(target.time_us, now)
        return gate.count("sent")

    # ------------------------------------------------------------ origin
    async def _origin_loop(self) -> None:
        c = self.config
        lat, lon = round(c.origin_lat_deg * 1e7), round(c.origin_lon_deg * 1e7)
        while True:
            if self._connected and not self._origin_ok:
                self.counters["origin_attempts"] += 1
                if c.profile == "ardupilot":
                    await self._send("COMMAND_INT", {
                        "target_system": self.system_id, "target_component": 1, "frame": 0,
                        "command": MAV_CMD_DO_SET_GLOBAL_ORIGIN, "current": 0,
                        "autocontinue": 0, "param1": 0.0, "param2": 0.0, "param3": 0.0,
                        "param4": 0.0, "x": lat, "y": lon, "z": float(c.origin_alt_m)},
                        (self.system_id, 1))
                else:
                    await self._send("SET_GPS_GLOBAL_ORIGIN", {
                        "target_system": self.system_id, "latitude": lat, "longitude": lon,
                        "altitude": round(c.origin_alt_m * 1000),
                        "time_usec": self.clock_ns() // 1000}, (self.system_id, 0))
            await asyncio.sleep(c.origin_retry_s)

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
                await self._send("TIMESYNC", {"tc1": now, "ts1": int(fields["ts1"]),
                                              "target_system": msg.system_id,
                                              "target_component": msg.component_id})
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
        if not self._origin_ok and origin_seen(item):
            self._origin_ok = True
            self.statustext("EKF origin confirmed")
        self._hub.publish(item)

    def _check_reboot(self, boot_ms: int) -> None:
        """time_boot_ms stepping back: the autopilot rebooted and lost its origin."""
        if self._last_boot_ms >= 0 and boot_ms + REBOOT_BACKSTEP_MS < self._last_boot_ms:
            self.reboots += 1
            self._origin_ok = False
            self.vision_gate.reset()
            self.target_gate.reset()
            self.statustext("autopilot reboot detected")
            self.streams.ask_all(self.clock_ns())
        self._last_boot_ms = boot_ms

    def latest(self, name: str) -> Telemetry | None:
        return self._hub.latest(name)

    def subscribe(self, *names: str) -> AsyncGenerator[Telemetry, None]:
        """Every new message of the given names; bounded, a slow reader loses the oldest."""
        return self._hub.subscribe(*names)

    @property
    def link_up(self) -> bool:
        return self._connected

    @property
    def origin_confirmed(self) -> bool:
        return self._origin_ok

    async def wait_link(self, up: bool = True, timeout_s: float = 5.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while self._connected != up:
            if time.monotonic() > deadline:
                return False
            await asyncio.sleep(0.02)
        return True

    def stats(self) -> dict[str, Any]:
        return {**self.counters, "link_up": self._connected, "origin_confirmed": self._origin_ok,
                "reboots": self.reboots,
                "vision": dict(self.vision_gate.counts),
                "landing_target": dict(self.target_gate.counts),
                "streams": self.stream_report()}

    def stream_report(self) -> dict[str, dict[str, Any]]:
        return self.streams.report(self.clock_ns())

    def stream_warnings(self) -> list[str]:
        return self.streams.missing()


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
