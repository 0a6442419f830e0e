"""The MAVSDK backend (native binding, mavsdk.asyncio, Mocap plugin) against the fake autopilot."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator
from typing import Any

import pytest

from mavlink_bridge.bridge import create_bridge
from mavlink_bridge.endpoint import parse_endpoint
from mavlink_bridge.errors import BackendError
from mavlink_bridge.fake_autopilot import FakeAutopilot
from mavlink_bridge.mavsdk_backend import MavsdkBridge, mavsdk_url
from mavlink_bridge.messages import LandingTargetFix

from .conftest import bridge_config, fake_config, stamp_age_errors_ms, truth_fix, wait_for


@contextlib.asynccontextmanager
async def mavsdk_wired(fake_kw: dict[str, Any], bridge_kw: dict[str, Any]
                       ) -> AsyncIterator[tuple[FakeAutopilot, MavsdkBridge]]:
    async with FakeAutopilot(fake_config(**fake_kw)) as ap:
        bridge = create_bridge(bridge_config(ap.local_port, backend="mavsdk", **bridge_kw))
        assert isinstance(bridge, MavsdkBridge)
        await bridge.start(timeout_s=5.0)
        try:
            yield ap, bridge
        finally:
            await bridge.stop()


async def send_some(ap: FakeAutopilot, bridge: MavsdkBridge, n: int) -> int:
    sent = 0
    for _ in range(n):
        sent += await bridge.send_fix(truth_fix(ap)) == "sent"
        await asyncio.sleep(0.04)
    return sent


def test_urls_translate_to_mavsdk_spelling() -> None:
    assert mavsdk_url(parse_endpoint("udpout:127.0.0.1:14550")) == "udpout://127.0.0.1:14550"
    assert mavsdk_url(parse_endpoint("tcp:10.0.0.2:5760")) == "tcpout://10.0.0.2:5760"
    assert mavsdk_url(parse_endpoint("serial:/dev/ttyS1:921600")) == "serial:///dev/ttyS1:921600"


async def test_mavsdk_ardupilot_odometry_frames_20_12_fused_and_origin_set() -> None:
    async with mavsdk_wired({"system_id": 42, "origin_fail_first": 2}, {}) as (ap, bridge):
        assert bridge.system_id == 42  # adopted the autopilot's sysid
        sent = await send_some(ap, bridge, 5)
        assert sent == 5
        assert await wait_for(lambda: len(ap.vision) == 5)
        assert {(r.name, r.frame_id, r.child_frame_id, r.estimator_type, r.reason)
                for r in ap.vision} == {("ODOMETRY", 20, 12, 2, "fused")}
        assert await wait_for(lambda: bridge.origin_confirmed, 5.0)
        assert ap.origin == (47.39, 8.54, 400.0)
        assert {h.component_id for h in ap.heartbeats if h.system_id == 42} == {197}
        assert await wait_for(lambda: bridge.latest("DISTANCE_SENSOR") is not None)


async def test_mavsdk_px4_vpe_with_timesync_and_landing_target() -> None:
    async with mavsdk_wired({"profile": "px4", "timesync_samples_required": 10},
                            {"profile": "px4"}) as (ap, bridge):
        assert await wait_for(lambda: ap.timesync_synced, 5.0)
        sent = await send_some(ap, bridge, 5)
        assert await wait_for(lambda: len(ap.vision) == sent)
        assert {(r.name, r.reason) for r in ap.vision} == {("VISION_POSITION_ESTIMATE", "fused")}
        # converted stamps carry their true age to half a TIMESYNC round trip, however late
        # the message came (an unconverted stamp is off by the companion's uptime)
        half_rtt_ms = ap.config.timesync_max_rtt_ms / 2
        assert all(abs(e) <= half_rtt_ms for e in stamp_age_errors_ms(ap)), stamp_age_errors_ms(ap)
        lt = LandingTargetFix(time.monotonic_ns() // 1000, (0.0, 0.0, 5.0), (1.0, 2.0, 0.0))
        assert await bridge.send_landing_target(lt) == "sent"
        assert await wait_for(lambda: len(ap.landing_targets) == 1)
        assert (ap.landing_targets[0]["frame"], ap.landing_targets[0]["accepted"]) == (1, True)


async def test_mavsdk_without_autopilot_fails_with_one_line() -> None:
    bridge = MavsdkBridge(bridge_config(9, backend="mavsdk", endpoint="udpout:127.0.0.1:9"))
    with pytest.raises(BackendError, match="no autopilot"):
        await bridge.start(timeout_s=0.5)


async def test_mavsdk_link_drop_and_reboot_are_handled() -> None:
    async with mavsdk_wired({}, {}) as (ap, bridge):
        assert await wait_for(lambda: bridge.origin_confirmed, 5.0)
        await asyncio.sleep(max(0.0, 1.2 - ap.boot_s()))
        ap.reboot(silent_s=0.3)
        assert await wait_for(lambda: bridge.reboots == 1, 5.0)
        assert await wait_for(lambda: ap.origin is not None and bridge.origin_confirmed, 5.0)
        ap.drop_link(8.0)
        assert await bridge.wait_link(False, 8.0), "MAVSDK never reported the link down"
        assert await bridge.send_fix(truth_fix(ap)) == "no_link"
