"""``companion fake-autopilot`` as a user runs it: a separate process, a JSON summary."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import sys
from pathlib import Path

from mavlink_bridge.bridge import PymavlinkBridge

from .conftest import DIAG_COV, bridge_config

ROOT = Path(__file__).resolve().parents[2]


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def test_cli_fake_autopilot_judges_and_summarises(tmp_path: Path) -> None:
    from mavlink_bridge.messages import VisionFix

    port = free_udp_port()
    summary = tmp_path / "summary.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "companion", "fake-autopilot", "--profile", "ardupilot",
        "--endpoint", f"udpin:127.0.0.1:{port}", "--seconds", "6", "--origin-fail-first", "2",
        "--summary", str(summary), "--streams", "all", "--judge", "truth", cwd=ROOT, env=env,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    bridge = PymavlinkBridge(bridge_config(port, heartbeat_rate_hz=2.0, link_timeout_s=3.0))
    try:
        await bridge.start()
        bridge.report_health("ok")
        assert await bridge.wait_link(True, 5.0), "fake autopilot process never answered"
        sent = 0
        for _ in range(20):
            att = bridge.latest("ATTITUDE")
            pos = bridge.latest("LOCAL_POSITION_NED")
            if att is not None and pos is not None:
                fix = VisionFix(pos.received_ns // 1000,
                                (pos.value.north_m, pos.value.east_m, pos.value.down_m),
                                (att.value.roll_rad, att.value.pitch_rad, att.value.yaw_rad),
                                DIAG_COV)
                sent += await bridge.send_fix(fix) == "sent"
            await asyncio.sleep(0.05)
        assert sent >= 5
        assert await asyncio.wait_for(proc.wait(), 10.0) == 0
    finally:
        await bridge.stop()
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    data = json.loads(summary.read_text())
    assert data["profile"] == "ardupilot"
    assert data["vision_received"] == sent and data["vision_accepted"] == sent
    assert [c["result"] for c in data["commands"] if c["command"] == 611][:3] == [4, 4, 0]
    assert data["origin"] == [47.39, 8.54, 400.0]
    assert data["companion_heartbeats"] >= 2
