"""The demo's fake autopilot in a process of its own (issue 23): it flies, answers on
UDP loopback and reports what it received, and its CPU is not the companion's."""

from __future__ import annotations

import asyncio
import time

from pymavlink import mavutil

from companion.demo_autopilot import AutopilotProcess
from companion.sim.scenario import load_scenario
from mavlink_bridge.fake_autopilot import FakeAutopilotConfig


async def _talk(fake: AutopilotProcess) -> int:
    """Send HEARTBEATs as a companion would; -> HEARTBEATs heard back from the fake."""
    link = mavutil.mavlink_connection(f"udpout:127.0.0.1:{fake.local_port}",
                                      source_system=1, source_component=191)
    heard = 0
    try:
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and heard < 2:
            link.mav.heartbeat_send(18, 8, 0, 0, 4)  # onboard controller, invalid autopilot
            await asyncio.sleep(0.2)
            while (msg := link.recv_match(type="HEARTBEAT", blocking=False)) is not None:
                heard += msg.get_srcSystem() == 1 and msg.get_srcComponent() == 1
    finally:
        link.close()
    return heard


def test_the_fake_autopilot_flies_in_its_own_process_and_reports() -> None:
    fake = AutopilotProcess(FakeAutopilotConfig(endpoint="udpin:127.0.0.1:0"),
                            load_scenario("survey"))

    async def run() -> int:
        await fake.start()
        try:
            assert fake.local_port > 0
            assert abs(time.monotonic_ns() - fake.start_ns) < 30e9  # one clock for both
            return await _talk(fake)
        finally:
            await fake.stop()

    heard = asyncio.run(run())
    assert heard >= 1, "the fake autopilot never answered"
    summary = fake.summary()
    assert summary["companion_heartbeats"] >= 1  # it received ours, over there
    assert summary["flight_s"] > 0.2
    assert fake.accepted() == [] and fake.accepted_count == 0  # no vision message was sent
    assert fake.cpu_s > 0.0  # its own CPU, measured in its process
