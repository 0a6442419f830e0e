"""Issue 24, link errors: a TCP autopilot that refuses the first connection is retried with
back-off (docs/mavlink.md says tcp reconnects), and a link that never comes up says so every
few seconds ("waiting for heartbeat"), not once at INFO."""

from __future__ import annotations

import asyncio
import logging

import pytest

from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.link import WAITING_LOG_S, MavlinkLink
from tests.test_monitoring import free_port


async def test_a_refused_tcp_connection_is_retried_until_the_autopilot_listens() -> None:
    port = free_port()
    link = MavlinkLink(MavlinkConfig(endpoint=f"tcp:127.0.0.1:{port}",
                                     reconnect_backoff_s=0.05))
    await link.start()  # refused: not an error for tcp
    try:
        assert link.connection is None
        await asyncio.sleep(0.4)
        failed_before = link.counters["open_errors"]
        assert failed_before >= 2  # retried, with back-off (0.05, 0.1, 0.2 ... s)
        assert failed_before <= 6
        accepted: list[asyncio.StreamWriter] = []

        async def on_client(_r: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            accepted.append(writer)

        server = await asyncio.start_server(on_client, "127.0.0.1", port)
        async with server:
            for _ in range(100):
                if accepted:
                    break
                await asyncio.sleep(0.02)
            assert accepted, "the link never connected once the port listened"
            assert link.connection is not None and link.counters["reconnects"] == 1
            for writer in accepted:
                writer.close()
    finally:
        await link.stop()


async def test_other_first_open_failures_still_raise_at_once() -> None:
    """A port in use is not going to fix itself: one LinkOpenError, at once."""
    from mavlink_bridge.errors import LinkOpenError

    first = MavlinkLink(MavlinkConfig(endpoint="udpin:127.0.0.1:0"))
    await first.start()
    try:
        second = MavlinkLink(MavlinkConfig(endpoint=f"udpin:127.0.0.1:{first.local_port}"))
        with pytest.raises(LinkOpenError, match="in use"):
            await second.start()
    finally:
        await first.stop()


async def test_a_link_that_never_comes_up_says_so_every_few_seconds(
        caplog: pytest.LogCaptureFixture) -> None:
    now_ns = [0]
    link = MavlinkLink(MavlinkConfig(endpoint="udpout:127.0.0.1:9"),
                       clock_ns=lambda: now_ns[0])
    caplog.set_level(logging.INFO, logger="mavlink_bridge.link")

    def waiting_lines_at(seconds: float) -> int:
        now_ns[0] = int(seconds * 1e9)
        link._check_link_timeout()  # what the heartbeat task does every period
        return sum("waiting for heartbeat from the autopilot on udpout:127.0.0.1:9" in r.message
                   and r.levelno == logging.WARNING for r in caplog.records)

    assert waiting_lines_at(1.0) == 0
    assert waiting_lines_at(WAITING_LOG_S - 0.1) == 0
    assert waiting_lines_at(WAITING_LOG_S + 0.1) == 1
    assert waiting_lines_at(WAITING_LOG_S + 2.0) == 1  # not every heartbeat period
    assert waiting_lines_at(2 * WAITING_LOG_S + 0.1) == 2
    assert waiting_lines_at(6 * WAITING_LOG_S + 0.1) == 3  # a stall: one line, not four
    assert "(30 s)" in caplog.records[-1].message
