"""Issue 24, connection strings: every spelling of docs/mavlink.md's table (mavutil,
MAVProxy, MAVSDK, MAVROS) opens what the table says, one test per row; the rest is refused
with one line naming the string."""

from __future__ import annotations

import asyncio
import os
import pty
import re
from pathlib import Path

import pytest

from mavlink_bridge.endpoint import open_connection, parse_endpoint
from mavlink_bridge.errors import EndpointError

DOC = Path(__file__).resolve().parents[2] / "docs" / "mavlink.md"


def documented_spellings() -> list[tuple[str, str]]:
    text = DOC.read_text(encoding="utf-8")
    table = text.split("<!-- spellings: begin -->")[1].split("<!-- spellings: end -->")[0]
    rows = [line for line in table.splitlines() if line.startswith("| `")]
    pairs = []
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        spelling, opened = cells[0].strip("`"), cells[-1].strip("`")
        pairs.append((spelling, opened))
    return pairs


SPELLINGS = documented_spellings()


def test_the_table_covers_the_spellings_the_issue_names() -> None:
    assert len(SPELLINGS) >= 20
    named = {"udp:127.0.0.1:14550", "127.0.0.1:14550", "/dev/ttyACM0:57600",
             "/dev/ttyACM0,57600", "serial:///dev/ttyACM0:57600", "udpin://0.0.0.0:14540",
             "udp://:14540", "udpout://192.168.1.12:14550", "tcp://127.0.0.1:5760",
             "tcpin:0.0.0.0:5760", "udpin:0.0.0.0:14550", "udpout:192.168.1.12:14550",
             "tcp:127.0.0.1:5760"}
    assert named <= {s for s, _ in SPELLINGS}


@pytest.mark.parametrize(("spelling", "opened"), SPELLINGS, ids=[s for s, _ in SPELLINGS])
def test_each_documented_spelling_opens_what_the_table_says(spelling: str, opened: str) -> None:
    endpoint = parse_endpoint(spelling)
    assert str(endpoint) == opened
    assert parse_endpoint(opened) == endpoint  # the canonical form reads back the same


@pytest.mark.parametrize(("spec", "why"), [
    ("garbage", "expected"),
    ("14550", "expected"),
    ("udpbcast:192.168.1.255:14550", "UDP broadcast is not supported"),
    ("serial_flowcontrol:///dev/ttyS0:57600", "flow control is not supported"),
    ("udp://0.0.0.0:14555@192.168.1.12:14550", "BIND@REMOTE"),
    ("udpout://:14550", "needs a host"),
    ("tcp:host", "expected tcp:HOST:PORT"),
    ("udpin:0.0.0.0:70000", "port must be 0..65535"),
    ("/dev/ttyACM0:12345", "unsupported baud rate 12345"),
    ("serial:/dev/ttyS0:0", "unsupported baud rate 0"),
    ("ftp://host:21", "unknown scheme"),
])
def test_other_strings_are_refused_with_one_line_naming_them(spec: str, why: str) -> None:
    with pytest.raises(EndpointError) as err:
        parse_endpoint(spec)
    message = str(err.value)
    assert "\n" not in message
    assert repr(spec) in message and why in message


async def test_mavsdk_and_mavutil_udp_spellings_really_listen() -> None:
    """``udpin://`` (MAVSDK) and ``udp:`` (mavutil) bind: a datagram sent to the bound port
    arrives."""
    for spelling in ("udpin://127.0.0.1:0", "udp:127.0.0.1:0", "127.0.0.1:0"):
        got: list[bytes] = []
        conn = await open_connection(parse_endpoint(spelling), got.append)
        loop = asyncio.get_running_loop()
        sender, _ = await loop.create_datagram_endpoint(
            asyncio.DatagramProtocol, remote_addr=("127.0.0.1", conn.local_port))
        sender.sendto(b"hello")
        for _ in range(100):
            if got:
                break
            await asyncio.sleep(0.01)
        sender.close()
        conn.close()
        assert got == [b"hello"], spelling


async def test_mavsdk_and_mavproxy_serial_spellings_open_the_device_not_a_mangled_path() -> None:
    """``serial:///dev/X:57600`` used to open the device ``///dev/X``; each serial spelling
    now opens the device itself (a pty here) at the baud rate."""
    master, slave = pty.openpty()
    device = os.ttyname(slave)
    try:
        for spelling in (f"serial://{device}:57600", f"{device}:57600", f"{device},57600",
                         device):
            endpoint = parse_endpoint(spelling)
            assert endpoint.device == device
            got: list[bytes] = []
            conn = await open_connection(endpoint, got.append)
            os.write(master, b"ping")
            for _ in range(100):
                if got:
                    break
                await asyncio.sleep(0.01)
            conn.close()
            assert b"".join(got) == b"ping", spelling
    finally:
        os.close(master)
        os.close(slave)


def test_the_doc_names_the_mavsdk_deprecation() -> None:
    text = DOC.read_text(encoding="utf-8")
    assert re.search(r"MAVSDK 2 and later deprecate `udp://`", text)
