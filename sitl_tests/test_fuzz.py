"""Fuzzing, bounded: the companion's MAVLink input path and its frame decoders.

Each property runs a fixed number of hypothesis examples (``FUZZ_EXAMPLES``, env
``LMC_FUZZ_EXAMPLES`` to run more) with a per-example deadline as the hang guard.  The
properties: nothing but the documented outcome ever comes out -- the MAVLink receive path
never raises, whatever the bytes; an image file decodes to an HxWx3 uint8 image or raises
:class:`ImageProblem`; the perception returns a :class:`FrameResult` for any HxWx3 frame.
"""

from __future__ import annotations

import os
import struct
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from companion.app import FrameResult
from companion.core.images import ImageProblem, read_image
from companion.demo import map_landmarks
from companion.perception import Perception
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sources.base import Frame
from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.link import MavlinkLink

FUZZ_EXAMPLES = int(os.environ.get("LMC_FUZZ_EXAMPLES", "500"))
DEADLINE_MS = 2000  # one example taking this long counts as a hang
FUZZED: Counter[str] = Counter()  # inputs tried per target, printed for docs/reliability.md

# what the companion reads from an autopilot, plus whatever else may arrive
HANDLED = ("HEARTBEAT", "ATTITUDE", "SYSTEM_TIME", "TIMESYNC", "GLOBAL_POSITION_INT",
           "LOCAL_POSITION_NED", "DISTANCE_SENSOR", "COMMAND_ACK", "GPS_GLOBAL_ORIGIN",
           "HOME_POSITION", "EKF_STATUS_REPORT", "STATUSTEXT", "ALTITUDE", "RANGEFINDER")
HANDLED_IDS = [int(getattr(mavlink2, f"MAVLINK_MSG_ID_{n}")) for n in HANDLED
               if hasattr(mavlink2, f"MAVLINK_MSG_ID_{n}")]
ALL_IDS = sorted(mavlink2.mavlink_map)


def frame_v2(msg_id: int, payload: bytes, seq: int = 0, sysid: int = 1, compid: int = 1) -> bytes:
    """A MAVLink 2 frame with a correct CRC around an arbitrary payload (any field bits:
    NaN, huge integers, unterminated strings), so the bytes get past the parser."""
    cls = mavlink2.mavlink_map[msg_id]
    size = cls.unpacker.size
    payload = payload[:size].rstrip(b"\x00") or b"\x00"  # MAVLink 2 trims trailing zeros
    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, seq & 0xFF, sysid, compid,
                         msg_id & 0xFFFF, msg_id >> 16)
    crc = mavlink2.x25crc(header[1:] + payload)
    crc.accumulate(bytes([cls.crc_extra]))
    return header + payload + struct.pack("<H", crc.crc)


def heartbeat() -> bytes:
    return frame_v2(mavlink2.MAVLINK_MSG_ID_HEARTBEAT,
                    struct.pack("<IBBBBB", 0, 2, 3, 0x81, 4, 3))


def fresh_link(signing: bool = False, tmp: Path | None = None) -> MavlinkLink:
    cfg = MavlinkConfig(endpoint="udpout:127.0.0.1:9", set_origin=False)
    if signing and tmp is not None:
        key = tmp / "key"
        key.write_bytes(bytes(range(32)))
        cfg = MavlinkConfig(endpoint="udpout:127.0.0.1:9", set_origin=False,
                            signing_key_file=str(key))
    link = MavlinkLink(cfg)
    link.codec.set_writer(lambda _data: None)  # answers (TIMESYNC) go nowhere
    return link


raw_bytes = st.binary(min_size=0, max_size=600)
messages = st.lists(st.tuples(st.sampled_from(HANDLED_IDS + ALL_IDS), st.binary(max_size=255),
                              st.integers(0, 255), st.integers(0, 255)), min_size=1, max_size=8)
mutations = st.lists(st.tuples(st.integers(0, 10_000), st.integers(1, 255)), max_size=4)


def mutate(data: bytes, flips: list[tuple[int, int]], cut: int | None) -> bytes:
    buf = bytearray(data)
    for pos, x in flips:
        if buf:
            buf[pos % len(buf)] ^= x
    return bytes(buf[:cut] if cut is not None else buf)


@settings(max_examples=FUZZ_EXAMPLES, deadline=DEADLINE_MS, derandomize=True)
@given(datagrams=st.lists(raw_bytes, min_size=1, max_size=5))
def test_fuzz_mavlink_raw_bytes(datagrams: list[bytes]) -> None:
    """Random datagrams into the companion's receive path: never raises, counts them."""
    link = fresh_link()
    for data in datagrams:
        link._on_bytes(data)
    FUZZED["mavlink_raw"] += 1
    assert link.codec.rx.bytes == sum(map(len, datagrams))


@settings(max_examples=FUZZ_EXAMPLES, deadline=DEADLINE_MS, derandomize=True)
@given(msgs=messages, flips=mutations, cut=st.one_of(st.none(), st.integers(0, 400)),
       datagram=st.booleans())
def test_fuzz_mavlink_structured(msgs: list[tuple[int, bytes, int, int]],
                                 flips: list[tuple[int, int]], cut: int | None,
                                 datagram: bool) -> None:
    """Well-framed messages with arbitrary field bits (after a genuine heartbeat, so they
    reach telemetry conversion, reboot detection and TIMESYNC), some with bytes flipped or
    cut: the receive path never raises and the link survives."""
    link = fresh_link()
    link._on_bytes(heartbeat())
    assert link.link_up
    stream = b"".join(frame_v2(i, p, seq, 1, c) for i, p, seq, c in msgs)
    data = mutate(stream, flips, cut)
    if datagram:
        link._on_bytes(data)
    else:  # a serial port: the same bytes in arbitrary chunks
        for k in range(0, len(data), 7):
            link._on_bytes(data[k:k + 7])
    link._on_bytes(heartbeat())
    FUZZED["mavlink_structured"] += 1
    assert link.codec.rx.packets >= 2


@settings(max_examples=FUZZ_EXAMPLES // 3, deadline=DEADLINE_MS, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(msgs=messages, flips=mutations)
def test_fuzz_mavlink_signed_link(tmp_path: Path, msgs: list[tuple[int, bytes, int, int]],
                                  flips: list[tuple[int, int]]) -> None:
    """With signing on, unsigned and mangled messages are refused and counted, never raise,
    and never take the link up; only the names in ``allow_unsigned`` (RADIO_STATUS) pass."""
    link = fresh_link(signing=True, tmp=tmp_path)
    data = mutate(b"".join(frame_v2(i, p, s, 1, c) for i, p, s, c in msgs), flips, None)
    link._on_bytes(data)
    FUZZED["mavlink_signed"] += 1
    allowed = sum(1 for i, *_ in msgs if i == mavlink2.MAVLINK_MSG_ID_RADIO_STATUS)
    assert not link.link_up and link.codec.rx.packets <= allowed


def _encoded(kind: str) -> bytes:
    image = np.zeros((24, 32, 3), np.uint8)
    cv2.rectangle(image, (4, 4), (20, 16), (40, 200, 90), -1)
    ok, buf = cv2.imencode(kind, image)
    assert ok
    return buf.tobytes()


SEEDS = {".png": _encoded(".png"), ".jpg": _encoded(".jpg")}


@settings(max_examples=FUZZ_EXAMPLES, deadline=DEADLINE_MS, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(suffix=st.sampled_from([".png", ".jpg"]), flips=mutations,
       cut=st.one_of(st.none(), st.integers(0, 2000)), junk=st.binary(max_size=64),
       random=st.booleans())
def test_fuzz_image_decoder(tmp_path: Path, suffix: str, flips: list[tuple[int, int]],
                            cut: int | None, junk: bytes, random: bool) -> None:
    """Mangled PNG/JPEG files (bytes flipped, cut short, junk appended) or pure junk: an
    HxWx3 uint8 image or an ImageProblem, nothing else."""
    data = junk if random else mutate(SEEDS[suffix], flips, cut) + junk
    path = tmp_path / f"frame{suffix}"
    path.write_bytes(data)
    FUZZED["image_files"] += 1
    try:
        image = read_image(path)
    except ImageProblem as problem:
        assert problem.reason in ("missing", "unreadable", "truncated", "corrupt")
        return
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3


@pytest.fixture(scope="module")
def perception() -> Perception:
    sim = Simulator(load_scenario("hover"))
    landmarks, references = map_landmarks(sim)
    return Perception(sim.scenario.camera, landmarks, references)


@settings(max_examples=max(20, FUZZ_EXAMPLES // 10), deadline=DEADLINE_MS * 2,
          derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                   HealthCheck.too_slow])
@given(shape=st.sampled_from([(480, 640, 3), (480, 640, 3), (240, 320, 3), (1, 1, 3),
                              (481, 640, 3), (480, 641, 3)]),
       fill=st.sampled_from(["noise", "zeros", "max", "stripes"]), seed=st.integers(0, 2**16))
def test_fuzz_perception_frames(perception: Perception, shape: tuple[int, int, int],
                                fill: str, seed: int) -> None:
    """Any HxWx3 uint8 frame -- noise, black, saturated, stripes, wrong sizes -- gives a
    FrameResult; a frame not of the camera's size is flagged bad and never gives a fix."""
    rng = np.random.default_rng(seed)
    if fill == "noise":
        image = rng.integers(0, 256, shape, dtype=np.uint8)
    elif fill == "stripes":
        image = np.zeros(shape, np.uint8)
        image[:: 1 + seed % 7] = 255
    else:
        image = np.full(shape, 0 if fill == "zeros" else 255, np.uint8)
    FUZZED["perception_frames"] += 1
    result = perception.process(Frame(seed, 1_000_000 + seed, image))
    assert isinstance(result, FrameResult)
    cam = perception.camera
    if shape[:2] != (cam.height, cam.width):
        assert result.bad_frame and result.fix is None


def test_fuzz_counts_reported() -> None:
    """Runs last in this module: prints how many inputs each target got (for the docs)."""
    print("fuzzed inputs:", dict(FUZZED))
