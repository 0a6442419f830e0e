"""Real peers read the companion's messages: pymavlink's mavutil and MAVProxy.

mavutil plays the autopilot directly; MAVProxy routes between the companion (its master) and
the fake autopilot (its output) and logs what it parsed from the companion to a tlog.
"""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")  # before mavutil is imported: MAVLink 2 framing

import asyncio
import shutil
import socket
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from mavlink_bridge.bridge import PymavlinkBridge

from .conftest import DIAG_COV, bridge_config, fake_config, wait_for

MAVPROXY = shutil.which("mavproxy.py") or str(Path(sys.executable).parent / "mavproxy.py")


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def recv(conn: Any, kind: str, timeout_s: float = 3.0) -> Any:
    """Blocking mavutil read, off the event loop so the companion keeps running."""
    return await asyncio.to_thread(conn.recv_match, type=kind, blocking=True, timeout=timeout_s)


async def test_mavutil_reads_heartbeat_statustext_and_vision() -> None:
    from mavlink_bridge.messages import VisionFix

    port = free_udp_port()
    ap = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=7,
                                    source_component=1)
    bridge = PymavlinkBridge(bridge_config(port, set_origin=False))
    await bridge.start()
    try:
        bridge.report_health("ok")
        hb = await recv(ap, "HEARTBEAT")
        assert hb is not None and hb.get_srcComponent() == 197 and hb.type == 18
        for _ in range(30):  # play the autopilot until the companion sees us
            ap.mav.heartbeat_send(2, 3, 0, 0, 4)
            if bridge.link_up:
                break
            await asyncio.sleep(0.05)
        assert bridge.link_up and bridge.link.autopilot_sysid == 7
        fix = VisionFix(time.monotonic_ns() // 1000, (1.0, -2.0, -3.0), (0.0, 0.1, 1.2),
                        DIAG_COV, quality_percent=77, reset_counter=2)
        assert await bridge.send_fix(fix) == "sent"
        odo = await recv(ap, "ODOMETRY")
        assert odo is not None and odo.get_srcSystem() == 7
        assert (odo.frame_id, odo.child_frame_id, odo.quality, odo.reset_counter) == (20, 12, 77, 2)
        assert (odo.x, odo.y, odo.z) == pytest.approx((1.0, -2.0, -3.0))
        bridge.statustext("hello mavutil")
        txt = await recv(ap, "STATUSTEXT")
        assert txt is not None and txt.text == "LMC: hello mavutil"
    finally:
        await bridge.stop()
        ap.close()


def companion_messages_in_tlog(folder: Path) -> dict[str, int]:
    """Count, by type, what MAVProxy logged from component 197 (the companion)."""
    tlogs = list(folder.rglob("mav.tlog"))
    assert tlogs, "MAVProxy wrote no tlog"
    log = mavutil.mavlink_connection(str(tlogs[0]))
    seen: dict[str, int] = {}
    while (m := log.recv_match()) is not None:
        if m.get_srcComponent() == 197:
            seen[m.get_type()] = seen.get(m.get_type(), 0) + 1
    return seen


def logged(folder: Path, kind: str) -> int:
    """How many ``kind`` messages of the companion's MAVProxy's tlog holds so far."""
    if not list(folder.rglob("mav.tlog")):
        return 0
    return companion_messages_in_tlog(folder).get(kind, 0)


@pytest.mark.skipif(not os.path.exists(MAVPROXY), reason="mavproxy.py not installed")
async def test_mavproxy_routes_and_parses_the_companions_messages(tmp_path: Path) -> None:
    from mavlink_bridge.fake_autopilot import FakeAutopilot

    from .conftest import truth_fix

    master_port = free_udp_port()
    async with FakeAutopilot(fake_config()) as fake:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, MAVPROXY, f"--master=udpin:127.0.0.1:{master_port}",
            f"--out=udpout:127.0.0.1:{fake.local_port}", "--daemon", "--nowait", "--mav20",
            f"--state-basedir={tmp_path}", "--logfile=mav.tlog", "--default-modules=link",
            "--streamrate=-1", cwd=tmp_path, stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL)
        bridge = PymavlinkBridge(bridge_config(master_port, link_timeout_s=3.0))
        try:
            await bridge.start()
            bridge.report_health("ok")
            assert await bridge.wait_link(True, 15.0), "no autopilot heartbeat through MAVProxy"
            sent = 0
            for _ in range(10):
                sent += await bridge.send_fix(truth_fix(fake)) == "sent"
                await asyncio.sleep(0.05)
            bridge.statustext("through mavproxy")
            assert await wait_for(lambda: len(fake.vision) == sent, 3.0)
            assert {r.reason for r in fake.vision} == {"fused"}
            assert await wait_for(lambda: "LMC: through mavproxy" in fake.statustexts, 3.0)
            # MAVProxy writes its tlog from a thread of its own: let it catch up before it
            # is stopped (at load 5 the last ODOMETRY was still unwritten at terminate)
            await wait_for(lambda: logged(tmp_path, "ODOMETRY") >= sent, 5.0)
        finally:
            await bridge.stop()
            proc.terminate()
            await asyncio.wait_for(proc.wait(), 10.0)
    seen = companion_messages_in_tlog(tmp_path)
    assert seen.get("ODOMETRY") == sent and seen.get("HEARTBEAT", 0) >= 1
