"""The other transports: tcp <-> tcpin with reconnect, serial over a pseudo-terminal."""

from __future__ import annotations

import asyncio
import os
import tty

from mavlink_bridge.bridge import PymavlinkBridge
from mavlink_bridge.codec import Codec
from mavlink_bridge.fake_autopilot import FakeAutopilot

from .conftest import bridge_config, fake_config, stream_fixes, wait_for


async def test_tcp_client_reconnects_when_the_autopilot_comes_back() -> None:
    ap = FakeAutopilot(fake_config(endpoint="tcpin:127.0.0.1:0"))
    await ap.start()
    port = ap.local_port
    bridge = PymavlinkBridge(bridge_config(port, endpoint=f"tcp:127.0.0.1:{port}",
                                           reconnect_backoff_s=0.1))
    await bridge.start()
    try:
        bridge.report_health("ok")
        assert await bridge.wait_link(True, 3.0)
        await stream_fixes(ap, bridge, 3)
        assert await wait_for(lambda: len(ap.accepted()) == 3)
        await ap.stop()  # the TCP peer goes away
        assert await bridge.wait_link(False, 3.0)
        ap = FakeAutopilot(fake_config(endpoint=f"tcpin:127.0.0.1:{port}"))
        await ap.start()
        assert await bridge.wait_link(True, 5.0)
        assert bridge.link.counters["reconnects"] >= 1
        await stream_fixes(ap, bridge, 3)
        assert await wait_for(lambda: len(ap.accepted()) == 3)
    finally:
        await bridge.stop()
        await ap.stop()


async def test_companion_listens_udpin_and_the_autopilot_sends_udpout() -> None:
    """The other UDP direction: the autopilot speaks first, the companion answers it."""
    bridge = PymavlinkBridge(bridge_config(0, endpoint="udpin:127.0.0.1:0"))
    await bridge.start()
    try:
        port = bridge.link.local_port
        async with FakeAutopilot(fake_config(endpoint=f"udpout:127.0.0.1:{port}")) as ap:
            bridge.report_health("ok")
            assert await bridge.wait_link(True, 3.0)
            await stream_fixes(ap, bridge, 3)
            assert await wait_for(lambda: len(ap.accepted()) == 3)
    finally:
        await bridge.stop()


async def test_serial_link_over_a_pty() -> None:
    """The bridge opens the pty's slave as ``serial:DEVICE:BAUD``; the test plays autopilot."""
    master, slave = os.openpty()
    tty.setraw(master)
    path = os.ttyname(slave)
    autopilot = Codec(1, 1)

    def write(data: bytes) -> None:
        os.write(master, data)

    autopilot.set_writer(write)
    got: list[str] = []
    loop = asyncio.get_running_loop()
    loop.add_reader(master, lambda: got.extend(
        m.get_type() for m in autopilot.feed(os.read(master, 4096), False)))
    bridge = PymavlinkBridge(bridge_config(0, endpoint=f"serial:{path}:115200", set_origin=False))
    await bridge.start()
    try:
        for _ in range(20):
            autopilot.mav.heartbeat_send(2, 3, 0, 0, 4)
            if bridge.link_up:
                break
            await asyncio.sleep(0.05)
        assert bridge.link_up
        assert await wait_for(lambda: "HEARTBEAT" in got)
        bridge.statustext("over serial")
        assert await wait_for(lambda: "STATUSTEXT" in got)
    finally:
        await bridge.stop()
        loop.remove_reader(master)
        os.close(master)
        os.close(slave)
