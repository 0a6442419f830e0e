"""Signing, scripted faults (drop, reboot, latency, loss, corruption) and reconnects."""

from __future__ import annotations

import asyncio
import hashlib
import os
from pathlib import Path

import pytest

from mavlink_bridge.codec import Codec, load_signing_key
from mavlink_bridge.errors import SigningKeyError
from mavlink_bridge.messages import odometry_fields

from .conftest import stream_fixes, truth_fix, wait_for, wired

KEY = hashlib.sha256(b"landmark").digest()


def key_file(tmp_path: Path, content: bytes) -> str:
    p = tmp_path / "key"
    p.write_bytes(content)
    return str(p)


def test_key_file_formats(tmp_path: Path) -> None:
    assert load_signing_key(key_file(tmp_path, KEY)) == KEY
    assert load_signing_key(key_file(tmp_path, KEY.hex().encode() + b"\n")) == KEY
    assert load_signing_key(key_file(tmp_path, b"landmark\n")) == KEY  # MAVProxy passphrase
    with pytest.raises(SigningKeyError, match="empty"):
        load_signing_key(key_file(tmp_path, b"  \n"))
    with pytest.raises(SigningKeyError, match="No such file"):
        load_signing_key(str(tmp_path / "missing"))


async def test_signed_link_works_end_to_end(tmp_path: Path) -> None:
    async with wired({"signing_key": KEY},
                     {"signing_key_file": key_file(tmp_path, b"landmark")}) as (ap, bridge):
        await stream_fixes(ap, bridge, 3)
        assert await wait_for(lambda: len(ap.accepted()) == 3)
        assert ap.codec.rx.bad_signature == 0
        assert bridge.link.codec.rx.bad_signature == 0


async def test_unsigned_or_wrongly_signed_companion_is_dropped(tmp_path: Path) -> None:
    """The fake enforces signing: nothing from an unsigned or wrong-key companion is used."""
    wrong = key_file(tmp_path, b"wrong passphrase")
    for bridge_kw in ({}, {"signing_key_file": wrong}):
        async with wired({"signing_key": KEY}, bridge_kw, require_link=False) as (ap, b):
            assert await wait_for(lambda: ap.codec.rx.bad_signature >= 2)
            b.link.send("ODOMETRY", **odometry_fields(truth_fix(ap), "ardupilot"))
            assert await wait_for(lambda: ap.codec.rx.bad_signature >= 3)
            assert ap.vision == [] and ap.heartbeats == []
            if bridge_kw:
                # the companion with the wrong key rejects the autopilot too: no link
                assert await wait_for(lambda: b.link.codec.rx.bad_signature > 0)
                assert not b.link_up


async def test_link_drop_is_detected_and_recovered() -> None:
    async with wired() as (ap, bridge):
        ap.drop_link(1.0)
        assert await bridge.wait_link(False, 2.0)
        assert await bridge.send_fix(truth_fix(ap)) == "no_link"
        assert await bridge.wait_link(True, 3.0)
        assert await bridge.send_fix(truth_fix(ap)) == "sent"


async def test_reboot_is_detected_and_the_origin_is_set_again() -> None:
    async with wired() as (ap, bridge):
        assert await wait_for(lambda: bridge.origin_confirmed)
        await asyncio.sleep(max(0.0, 1.2 - ap.boot_s()))  # time_boot_ms must step back > 0.5 s
        first_attempts = bridge.origin_attempts
        ap.reboot(silent_s=0.3)
        assert ap.origin is None and ap.codec.mav.seq == 0
        assert await wait_for(lambda: bridge.link.reboots == 1, 3.0)
        assert await wait_for(lambda: ap.origin is not None and bridge.origin_confirmed, 3.0)
        assert bridge.origin_attempts > first_attempts
        assert await wait_for(lambda: "LMC: autopilot reboot detected" in ap.statustexts)


async def test_latency_jitter_and_loss_are_survived_and_counted() -> None:
    async with wired() as (ap, bridge):
        ap.faults.state.latency_s = 0.03
        ap.faults.state.jitter_s = 0.02
        ap.faults.state.loss_probability = 0.2
        results = await stream_fixes(ap, bridge, 30)
        await asyncio.sleep(0.2)
        sent = results.count("sent")
        assert ap.faults.counters.lost > 0 and ap.faults.counters.delayed > 0
        # every fix that arrived was fused: the gate accounts for latency
        assert 0 < len(ap.vision) < sent + 1
        assert {r.reason for r in ap.vision} <= {"fused"}


async def test_corrupted_bytes_from_the_autopilot_are_counted_not_fatal() -> None:
    async with wired() as (ap, bridge):
        ap.faults.state.corrupt_probability = 0.5
        await asyncio.sleep(1.0)
        rx = bridge.link.codec.rx
        assert rx.bad_crc + rx.bad_framing + rx.truncated + rx.unknown_id + rx.mavlink1 > 0
        assert bridge.link.link_up  # the half that got through keeps the link alive
        ap.faults.state.corrupt_probability = 0.0
        await stream_fixes(ap, bridge, 3)
        assert await wait_for(lambda: len(ap.accepted()) == 3)


def test_codec_signs_and_rejects_replays() -> None:
    """A signed frame fed twice: the second has an old timestamp and is rejected."""
    tx, rx = Codec(1, 1), Codec(1, 197)
    tx.enable_signing(KEY, 0, ())
    rx.enable_signing(KEY, 0, ())
    frames: list[bytes] = []
    tx.set_writer(frames.append)
    tx.mav.heartbeat_send(2, 3, 0, 0, 4)
    assert len(rx.feed(frames[0], True)) == 1
    assert rx.feed(frames[0], True) == [] and rx.rx.bad_signature == 1
    assert os.environ.get("MAVLINK20") in (None, "1")


def test_only_configured_messages_pass_unsigned() -> None:
    """With signing on, an unsigned HEARTBEAT is dropped, an unsigned RADIO_STATUS passes."""
    tx, rx = Codec(1, 1), Codec(1, 197)
    rx.enable_signing(KEY, 0, ("RADIO_STATUS",))
    frames: list[bytes] = []
    tx.set_writer(frames.append)
    tx.mav.heartbeat_send(2, 3, 0, 0, 4)
    tx.mav.radio_status_send(200, 190, 80, 0, 0, 0, 0)
    assert rx.feed(frames[0], True) == []
    assert [m.get_type() for m in rx.feed(frames[1], True)] == ["RADIO_STATUS"]
    assert rx.rx.bad_signature == 1
    with pytest.raises(SigningKeyError, match="unknown message name"):
        Codec(1, 1).enable_signing(KEY, 0, ("NOT_A_MESSAGE",))
