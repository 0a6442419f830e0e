"""Hostile input: garbage, truncated packets, wrong CRCs, unknown ids, MAVLink 1, a flood.

Everything is parsed or dropped and counted; nothing crashes; the heartbeat keeps going.
"""

from __future__ import annotations

import asyncio
import socket
import struct
import threading
import time

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mavlink_bridge.bridge import PymavlinkBridge
from mavlink_bridge.codec import Codec
from mavlink_bridge.config import MavlinkConfig

from .conftest import wait_for


def frames() -> tuple[Codec, list[bytes]]:
    out: list[bytes] = []
    c = Codec(1, 1)
    c.set_writer(out.append)
    return c, out


def heartbeat() -> bytes:
    c, out = frames()
    c.mav.heartbeat_send(2, 3, 0, 0, 4)
    return out[0]


def attitude(i: int) -> bytes:
    c, out = frames()
    c.mav.attitude_send(i, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0)
    return out[0]


def unknown_id_frame() -> bytes:
    payload = b"\x01\x02\x03"
    header = struct.pack("<BBBBBBBHB", 253, len(payload), 0, 0, 7, 1, 1, 0xBEEF, 0x0A)
    return header + payload + b"\x12\x34"


async def start_bridge() -> tuple[PymavlinkBridge, socket.socket, tuple[str, int]]:
    bridge = PymavlinkBridge(MavlinkConfig(endpoint="udpin:127.0.0.1:0", set_origin=False,
                                           heartbeat_rate_hz=5.0, link_timeout_s=5.0))
    await bridge.start()
    bridge.report_health("ok")
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    peer.setblocking(False)
    addr = ("127.0.0.1", bridge.link.local_port)
    peer.sendto(heartbeat(), addr)
    assert await bridge.wait_link(True, 2.0)
    return bridge, peer, addr


async def test_each_kind_of_bad_packet_is_counted() -> None:
    bridge, peer, addr = await start_bridge()
    try:
        rng = np.random.default_rng(7)
        good = attitude(1)
        bad_crc = bytearray(good)
        bad_crc[-1] ^= 0xFF
        c, v1 = frames()
        c.mav.heartbeat_send(2, 3, 0, 0, 4, force_mavlink1=True)
        for data in (rng.integers(0, 256, 300, dtype=np.uint8).tobytes().replace(b"\xfd", b"")
                     .replace(b"\xfe", b""), good[:-5], bytes(bad_crc), unknown_id_frame(),
                     v1[0], good):
            peer.sendto(data, addr)
        rx = bridge.link.codec.rx
        assert await wait_for(lambda: bridge.latest("ATTITUDE") is not None)
        assert rx.bad_framing >= 1 and rx.truncated == 1 and rx.bad_crc == 1
        assert rx.unknown_id == 1 and rx.mavlink1 == 1
        assert bridge.link.link_up
    finally:
        peer.close()
        await bridge.stop()


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(min_size=0, max_size=300), max_size=8), st.booleans())
def test_codec_feed_never_raises_and_accounts_for_every_byte(chunks: list[bytes],
                                                             datagram: bool) -> None:
    """Any byte sequence, cut anywhere, with a valid frame mixed in: no exception, and the
    valid frame still comes out when it arrives in its own datagram."""
    codec = Codec(1, 197)
    for chunk in chunks:
        codec.feed(chunk, datagram)
    assert codec.rx.bytes == sum(len(c) for c in chunks)
    if datagram:
        assert [m.get_type() for m in codec.feed(attitude(5), True)] == ["ATTITUDE"]


async def test_random_byte_streams_never_crash_the_parser() -> None:
    bridge, peer, addr = await start_bridge()
    try:
        rng = np.random.default_rng(1)
        for i in range(300):
            blob = bytearray(rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8))
            if i % 3 == 0:  # a valid frame with one flipped byte goes deeper into the parser
                blob = bytearray(attitude(i))
                blob[int(rng.integers(0, len(blob)))] ^= 0x55
            peer.sendto(bytes(blob), addr)
            if i % 50 == 49:
                await asyncio.sleep(0.02)  # do not overrun the kernel's socket buffer
        await asyncio.sleep(0.05)
        peer.sendto(attitude(999), addr)
        assert await wait_for(lambda: (a := bridge.latest("ATTITUDE")) is not None
                              and a.value.time_boot_ms == 999)
        rx = bridge.link.codec.rx
        assert rx.bad_crc + rx.bad_framing + rx.truncated + rx.unknown_id + rx.mavlink1 >= 200
        assert bridge.link.link_up
    finally:
        peer.close()
        await bridge.stop()


def _flood(addr: tuple[str, int], rate_hz: int, seconds: float, sent: list[int],
           heard: list[float]) -> None:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setblocking(False)
    packets = [attitude(i) for i in range(100)]
    hb = heartbeat()
    t0 = time.monotonic()
    n = 0
    while (now := time.monotonic()) - t0 < seconds:
        due = int((now - t0) * rate_hz)
        while n < due:
            s.sendto(packets[n % 100] if n % 500 else hb, addr)
            n += 1
        try:
            while True:
                s.recv(4096)
                heard.append(time.monotonic())
        except BlockingIOError:
            pass
        time.sleep(0.001)
    sent.append(n)
    s.close()


async def test_a_10k_per_second_flood_does_not_stall_the_heartbeat() -> None:
    bridge, peer, addr = await start_bridge()
    try:
        before = bridge.link.counters["heartbeats_sent"]
        sent: list[int] = []
        heard: list[float] = []
        t = threading.Thread(target=_flood, args=(addr, 10_000, 2.0, sent, heard))
        t.start()
        await asyncio.to_thread(t.join)
        during = bridge.link.counters["heartbeats_sent"] - before
        rx = bridge.link.codec.rx
        print(f"flood: sent {sent[0]}, parsed {rx.packets}, dropped_budget {rx.dropped_budget}, "
              f"heartbeats during 2 s at 5 Hz: {during}")
        assert sent[0] >= 10_000
        assert rx.packets + rx.dropped_budget >= 0.5 * sent[0]
        assert during >= 8  # nominal 10: the heartbeat did not stall
        assert bridge.link.link_up
    finally:
        peer.close()
        await bridge.stop()
