"""Shared helpers: a fake autopilot and a bridge wired over UDP loopback on free ports."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import replace
from typing import Any

from mavlink_bridge.bridge import PymavlinkBridge
from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.messages import VisionFix
from mavlink_bridge.streams import needed_streams

FAST_PERIODS = (
    ("HEARTBEAT", 0.1), ("ATTITUDE", 0.05), ("LOCAL_POSITION_NED", 0.1),
    ("GLOBAL_POSITION_INT", 0.1), ("SYSTEM_TIME", 0.5), ("DISTANCE_SENSOR", 0.1),
    ("EKF_STATUS_REPORT", 0.5), ("TIMESYNC", 0.05), ("HOME_POSITION", 0.2),
)
# what a companion with a range finder asks for (the strict fake sends nothing unasked)
ASKED = tuple((s.name, s.rate_hz) for s in needed_streams(30.0, rangefinder=True))
DIAG_COV = tuple(0.01 if k in (0, 6, 11) else (0.001 if k in (15, 18, 20) else 0.0)
                 for k in range(21))


def fake_config(**kw: Any) -> FakeAutopilotConfig:
    return replace(FakeAutopilotConfig(periods_s=FAST_PERIODS), **kw)


def bridge_config(port: int, **kw: Any) -> MavlinkConfig:
    base = MavlinkConfig(endpoint=f"udpout:127.0.0.1:{port}", origin_lat_deg=47.39,
                         origin_lon_deg=8.54, origin_alt_m=400.0, origin_retry_s=0.05,
                         heartbeat_rate_hz=5.0, link_timeout_s=0.6, rate_hz=30.0,
                         streams=ASKED)
    return replace(base, **kw)


@contextlib.asynccontextmanager
async def wired(fake_kw: dict[str, Any] | None = None,
                bridge_kw: dict[str, Any] | None = None, require_link: bool = True
                ) -> AsyncIterator[tuple[FakeAutopilot, PymavlinkBridge]]:
    """A running fake autopilot (udpin, port 0) and a bridge pointed at it, link up."""
    async with FakeAutopilot(fake_config(**(fake_kw or {}))) as ap:
        bridge = PymavlinkBridge(bridge_config(ap.local_port, **(bridge_kw or {})))
        async with bridge:
            bridge.report_health("ok")
            if require_link:
                assert await bridge.wait_link(True, 3.0), "link never came up"
            yield ap, bridge


def stamp_age_errors_ms(ap: FakeAutopilot) -> list[float]:
    """Each vision record's stated stamp age less its true age, in ms.

    The fake and the companion share one machine clock (the fake's is the same monotonic
    clock less ``boot_ns``), so a record's true age at its arrival is known exactly. A
    TIMESYNC offset is right to half the round trip of the samples it took (the fake keeps
    those under ``timesync_max_rtt_ms``), however late the message arrived; an unconverted
    stamp is off by the companion's whole uptime."""
    out = []
    for r in ap.vision:
        stamp_local_ms = r.time_usec / 1000 - ap.boot_ns / 1e6
        out.append(r.stamp_age_ms - (r.arrival_s * 1000 - stamp_local_ms))
    return out


async def wait_for(pred: Callable[[], bool], timeout_s: float = 3.0) -> bool:
    """Poll ``pred`` every 10 ms until it holds or ``timeout_s`` passes."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if pred():
            return True
        await asyncio.sleep(0.01)
    return pred()


def truth_fix(ap: FakeAutopilot, **kw: Any) -> VisionFix:
    """A fix at the fake's true pose, stamped now on the companion's clock."""
    s = ap.truth(ap.flight_s())
    base = VisionFix(time.monotonic_ns() // 1000, s.position_ned_m, s.attitude_rpy_rad, DIAG_COV,
                     quality_percent=90)
    return replace(base, **kw)


async def stream_fixes(ap: FakeAutopilot, bridge: PymavlinkBridge, n: int,
                       period_s: float = 0.034, **kw: Any) -> list[str]:
    out: list[str] = []
    for _ in range(n):
        out.append(await bridge.send_fix(truth_fix(ap, **kw)))
        await asyncio.sleep(period_s)
    return out
