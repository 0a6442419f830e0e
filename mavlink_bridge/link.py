"""The MAVLink link: transport + codec + heartbeat + telemetry cache, all on one event loop.

* HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID) is sent by a task of the
  application's own loop with ``system_status`` taken from the health the application reports
  through :meth:`MavlinkLink.report_health`; when the application stops reporting, the heartbeat
  says MAV_STATE_CRITICAL.  If the loop itself stalls, so does the heartbeat -- by design.
* The autopilot is the first component-1 sender of a HEARTBEAT whose autopilot field is not
  MAV_AUTOPILOT_INVALID; our system id becomes its system id (unless configured).
* Link up/down from the autopilot's heartbeat; a closed transport (TCP, serial) is reopened,
  and a TCP peer that refuses the first connection is retried, with back-off.  While no
  heartbeat comes, "waiting for heartbeat from the autopilot on ..." is logged every 5 s.
* TIMESYNC requests (tc1 == 0) are answered with our monotonic clock in ns.
* Incoming bytes beyond a byte budget are dropped unparsed and counted.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncGenerator, Callable
from typing import Any, Literal

from mavlink_bridge.codec import Codec, MAVLinkMessage, load_signing_key
from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.endpoint import Connection, Endpoint, open_connection, parse_endpoint
from mavlink_bridge.errors import LinkOpenError, MavlinkBridgeError
from mavlink_bridge.telemetry import Telemetry, TelemetryHub, convert

log = logging.getLogger(__name__)

HealthState = Literal["starting", "standby", "ok", "degraded", "failed"]
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
# MAV_STATE: BOOT 1, STANDBY 3, ACTIVE 4, CRITICAL 5, EMERGENCY 6
_MAV_STATE = {"starting": 1, "standby": 3, "ok": 4, "degraded": 5, "failed": 6}
MAV_STATE_CRITICAL = 5
MAV_SEVERITY_INFO = 6
REBOOT_BACKSTEP_MS = 500  # time_boot_ms going back this far means a reboot
WAITING_LOG_S = 5.0  # "waiting for heartbeat" is logged this often while the link is down


class MavlinkLink:
    """One link to one autopilot (see module doc).  Use as ``async with MavlinkLink(cfg):``."""

    def __init__(self, config: MavlinkConfig, clock_ns: Callable[[], int] = time.monotonic_ns):
        self.config = config
        self.endpoint: Endpoint = parse_endpoint(config.endpoint)
        self.clock_ns = clock_ns
        self.codec = Codec(config.system_id or 1, config.component_id)
        if config.signing_key_file:
            self.codec.enable_signing(load_signing_key(config.signing_key_file),
                                      config.signing_link_id, config.allow_unsigned)
        self.connection: Connection | None = None
        self.autopilot_sysid: int | None = None
        self.autopilot_type: int | None = None
        self.link_up = False
        self.link_changes = 0
        self.reboots = 0
        self.counters: dict[str, int] = {
            "heartbeats_sent": 0, "timesync_answered": 0, "queue_drops": 0,
            "reconnects": 0, "statustext_dropped": 0, "open_errors": 0,
        }
        self._last_ap_heartbeat_ns = 0
        self._last_boot_ms = -1
        self._health: HealthState = "starting"
        self._health_ns = clock_ns()
        self._health_stale = False
        self._hub = TelemetryHub(self.config.rx_queue_len, self.counters)
        self._tasks: list[asyncio.Task[None]] = []
        self._link_event = asyncio.Event()
        self._opened = asyncio.Event()
        self._text_queue: asyncio.Queue[tuple[str, int]] = asyncio.Queue(maxsize=16)
        self._budget = float(config.rx_budget_bytes_per_s)
        self._budget_ns = clock_ns()
        self.reboot_listeners: list[Callable[[], None]] = []
        #: called with (up) on every link change, and (name, arrival_ns) for every message
        #: from the autopilot (the stream watch measures rates with it)
        self.link_listeners: list[Callable[[bool], None]] = []
        self.rx_listeners: list[Callable[[str, int], None]] = []
        self._msg_listeners: list[Callable[[MAVLinkMessage], None]] = []
        self._started_ns = clock_ns()
        self._next_waiting_log_s = WAITING_LOG_S
        self._open_error = ""

    # ----------------------------------------------------------------- lifecycle
    async def start(self) -> None:
        """Open the endpoint and start the tasks.  A first open that fails raises
        LinkOpenError, except for ``tcp``: an autopilot (or SITL) that is not listening yet
        is retried with back-off, like a TCP peer that went away."""
        self._started_ns = self.clock_ns()
        try:
            await self._open()
        except LinkOpenError as err:
            if self.endpoint.kind != "tcp":
                raise
            self._open_error = str(err)
            log.warning("%s; retrying with back-off", err)
        self._tasks = [
            asyncio.create_task(self._supervise(), name="mavlink-supervise"),
            asyncio.create_task(self._heartbeat_loop(), name="mavlink-heartbeat"),
            asyncio.create_task(self._statustext_loop(), name="mavlink-statustext"),
        ]

    async def stop(self) -> None:
        for t in self._tasks:
            t.cancel()
        for t in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await t
        self._tasks = []
        if self.connection is not None:
            self.connection.close()
        self.codec.set_writer(None)

    async def __aenter__(self) -> MavlinkLink:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    @property
    def local_port(self) -> int:
        """Bound port (for udpin/tcpin on port 0 in tests), else the local socket port."""
        return 0 if self.connection is None else self.connection.local_port

    async def _open(self) -> None:
        self.connection = await open_connection(self.endpoint, self._on_bytes)
        self.codec.set_writer(self.connection.write)
        self._opened.set()

    async def _supervise(self) -> None:
        """Reopen a transport that closed (TCP peer gone, serial unplugged) or never opened
        (TCP refused), with back-off: ``reconnect_backoff_s``, doubled after each failure up
        to 8 times that."""
        while True:
            if self.connection is not None:
                await asyncio.shield(self.connection.closed)
                self.codec.set_writer(None)
                self._set_link(False)
            backoff_s = self.config.reconnect_backoff_s
            while True:
                await asyncio.sleep(backoff_s)
                try:
                    await self._open()
                    self.counters["reconnects"] += 1
                    self._open_error = ""
                    break
                except MavlinkBridgeError as err:
                    self.counters["open_errors"] += 1
                    self._open_error = str(err)
                    log.debug("reopen %s failed: %s", self.endpoint, err)
                    backoff_s = min(2 * backoff_s, 8 * self.config.reconnect_backoff_s)

    # ----------------------------------------------------------------- health + heartbeat
    def report_health(self, state: HealthState) -> None:
        """The application's own health; call it from the pipeline whenever it makes progress."""
        self._health = state
        self._health_ns = self.clock_ns()
        if self._health_stale:
            self._health_stale = False
            self.statustext("application responding again")

    def system_status(self) -> int:
        age_s = (self.clock_ns() - self._health_ns) * 1e-9
        if age_s > self.config.health_timeout_s:
            if not self._health_stale:
                self._health_stale = True
                self.statustext("application not responding", severity=2)
            return MAV_STATE_CRITICAL
        return _MAV_STATE[self._health]

    async def _heartbeat_loop(self) -> None:
        period_s = 1.0 / self.config.heartbeat_rate_hz
        loop = asyncio.get_running_loop()
        next_t = loop.time()
        while True:
            self.send_heartbeat()
            self._check_link_timeout()
            next_t += period_s
            now = loop.time()
            if next_t < now:  # we were stalled: do not burst to catch up
                next_t = now + period_s
            await asyncio.sleep(next_t - now)

    def send_heartbeat(self) -> None:
        self.codec.mav.heartbeat_send(MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID,
                                      0, 0, self.system_status())
        self.counters["heartbeats_sent"] += 1

    def _check_link_timeout(self) -> None:
        if self.link_up:
            age_s = (self.clock_ns() - self._last_ap_heartbeat_ns) * 1e-9
            if age_s > self.config.link_timeout_s:
                self._set_link(False)
        else:
            self._log_waiting()

    def _log_waiting(self) -> None:
        """While no autopilot heartbeat comes: a warning every WAITING_LOG_S seconds."""
        since_ns = max(self._started_ns, self._last_ap_heartbeat_ns)
        waited_s = (self.clock_ns() - since_ns) * 1e-9
        if waited_s < self._next_waiting_log_s:
            return
        self._next_waiting_log_s = (waited_s // WAITING_LOG_S + 1) * WAITING_LOG_S
        why = f"; cannot open it: {self._open_error}" if self._open_error else ""
        log.warning("waiting for heartbeat from the autopilot on %s (%.0f s%s)",
                    self.endpoint, waited_s, why)

    def _set_link(self, up: bool) -> None:
        if up == self.link_up:
            return
        self._next_waiting_log_s = WAITING_LOG_S
        self.link_up = up
        self.link_changes += 1
        self._link_event.set()
        self._link_event = asyncio.Event()
        log.info("autopilot link %s", "up" if up else "down")
        if up:
            self.statustext("link up")
        for listener in self.link_listeners:
            listener(up)

    async def wait_link(self, up: bool = True, timeout_s: float = 5.0) -> bool:
        """Wait until the link is ``up`` (or down); False on timeout."""
        async def _wait() -> None:
            while self.link_up != up:
                await self._link_event.wait()
        try:
            await asyncio.wait_for(_wait(), timeout_s)
        except TimeoutError:
            return False
        return True

    # ----------------------------------------------------------------- sending
    def send(self, name: str, **fields: Any) -> None:
        """Encode and send one message by name with pymavlink's ``<name>_send``."""
        getattr(self.codec.mav, f"{name.lower()}_send")(**fields)

    def statustext(self, text: str, severity: int = MAV_SEVERITY_INFO) -> None:
        """Queue a STATUSTEXT with the configured prefix (50 chars max; rate-limited)."""
        try:
            self._text_queue.put_nowait((self.config.statustext_prefix + text, severity))
        except asyncio.QueueFull:
            self.counters["statustext_dropped"] += 1

    async def _statustext_loop(self) -> None:
        while True:
            text, severity = await self._text_queue.get()
            self.codec.mav.statustext_send(severity, text.encode("utf-8")[:50])
            await asyncio.sleep(self.config.statustext_min_interval_s)

    # ----------------------------------------------------------------- receiving
    def _on_bytes(self, data: bytes) -> None:
        now = self.clock_ns()
        rate = self.config.rx_budget_bytes_per_s
        self._budget = min(float(rate), self._budget + (now - self._budget_ns) * 1e-9 * rate)
        self._budget_ns = now
        if self._budget < len(data):
            self.codec.rx.dropped_budget += 1
            return
        self._budget -= len(data)
        for msg in self.codec.feed(data, self.endpoint.datagram):
            try:
                self._dispatch(msg, now)
            except Exception:  # a malformed-but-parsed message must not kill the link
                self.codec.rx.parser_errors += 1
                log.debug("dispatch failed for %s", msg.get_type(), exc_info=True)

    def _dispatch(self, msg: MAVLinkMessage, now_ns: int) -> None:
        name = msg.get_type()
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if name == "HEARTBEAT":
            self._on_heartbeat(msg, sysid, compid, now_ns)
        if self.autopilot_sysid is None or sysid != self.autopilot_sysid:
            return
        if name == "TIMESYNC":
            self._answer_timesync(msg, sysid, compid, now_ns)
        for rx in self.rx_listeners:
            rx(name, now_ns)
        for fn in list(self._msg_listeners):
            fn(msg)
        boot_ms = getattr(msg, "time_boot_ms", None)
        if boot_ms is not None and compid == 1:
            self._check_reboot(int(boot_ms))
        value = convert(name, msg.to_dict())
        if value is None:
            return
        item = Telemetry(name, sysid, compid, now_ns, value)
        self._hub.publish(item)

    def _on_heartbeat(self, msg: MAVLinkMessage, sysid: int, compid: int, now_ns: int) -> None:
        if compid != 1 or msg.autopilot == MAV_AUTOPILOT_INVALID:
            return
        if self.autopilot_sysid is None:
            self.autopilot_sysid = sysid
            self.autopilot_type = int(msg.autopilot)
            if self.config.system_id == 0:
                self.codec.system_id = sysid
        if sysid == self.autopilot_sysid:
            self._last_ap_heartbeat_ns = now_ns
            self._set_link(True)

    def _answer_timesync(self, msg: MAVLinkMessage, sysid: int, compid: int, now_ns: int) -> None:
        if msg.tc1 != 0:
            return  # an answer to someone's request, not a request
        target = getattr(msg, "target_system", 0)
        if target not in (0, self.codec.system_id):
            return
        self.codec.mav.timesync_send(now_ns, msg.ts1)
        self.counters["timesync_answered"] += 1

    def _check_reboot(self, boot_ms: int) -> None:
        if self._last_boot_ms >= 0 and boot_ms + REBOOT_BACKSTEP_MS < self._last_boot_ms:
            self.reboots += 1
            self.statustext("autopilot reboot detected")
            for listener in self.reboot_listeners:
                listener()
        self._last_boot_ms = boot_ms

    def add_msg_listener(self, fn: Callable[[MAVLinkMessage], None]) -> None:
        """Call ``fn`` with every message from the autopilot (e.g. PARAM_VALUE)."""
        self._msg_listeners.append(fn)

    def remove_msg_listener(self, fn: Callable[[MAVLinkMessage], None]) -> None:
        with contextlib.suppress(ValueError):
            self._msg_listeners.remove(fn)

    # ----------------------------------------------------------------- telemetry API
    def latest(self, name: str) -> Telemetry | None:
        """The newest message of ``name`` from the autopilot, or None."""
        return self._hub.latest(name)

    def subscribe(self, *names: str) -> AsyncGenerator[Telemetry, None]:
        """Every new message of the given names; bounded, a slow reader loses the oldest."""
        return self._hub.subscribe(*names)

    def stats(self) -> dict[str, Any]:
        """Counters for monitoring: rx parser counts, link, drops."""
        out: dict[str, Any] = dict(self.counters)
        out["rx"] = self.codec.rx.as_dict()
        out["link_up"] = self.link_up
        out["reboots"] = self.reboots
        if self.connection is not None:
            out["tx_bytes_dropped"] = self.connection.bytes_dropped
        return out
