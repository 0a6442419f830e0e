"""MAVLink 2 framing over pymavlink: encode with real sequence numbers, parse robustly, sign.

``pymavlink.dialects.v20.ardupilotmega`` is imported directly, so the wire format is always
MAVLink 2 whatever ``MAVLINK20`` says.  Messages are sent with the generated ``*_send``
methods (``msg.pack()`` alone would not advance the sequence number), through a tiny
file-like sink that hands the bytes to the current transport.

Parsing never raises: garbage, truncated packets, bad CRCs, bad signatures, MAVLink 1 frames
and unknown ids are dropped and counted in :class:`RxCounters`.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TypeAlias

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from mavlink_bridge.errors import SigningKeyError

# pymavlink.dialects.v20.ardupilotmega.MAVLink_message; pymavlink ships no usable stubs here
MAVLinkMessage: TypeAlias = Any
# Signing timestamps count 10 us ticks since 2015-01-01 00:00:00 UTC (MAVLink signing spec).
_SIGNING_EPOCH_UNIX_S = 1_420_070_400


def signing_timestamp_now() -> int:
    """Current signing timestamp: 10 us units since 2015-01-01 UTC."""
    return int((time.time() - _SIGNING_EPOCH_UNIX_S) * 100_000)


def load_signing_key(path: str) -> bytes:
    """Read a 32-byte signing key.

    The file holds either 32 raw bytes, 64 hex digits, or a passphrase (hashed with SHA-256,
    as MAVProxy's ``signing setup PASSPHRASE`` does), so one file serves every tool.
    """
    try:
        raw = Path(path).read_bytes()
    except OSError as err:
        raise SigningKeyError(f"signing key file {path}: {err.strerror}") from err
    if len(raw) == 32:
        return raw
    try:
        text = raw.decode("utf-8").strip()
    except UnicodeDecodeError as err:
        raise SigningKeyError(f"signing key file {path}: expected 32 raw bytes, 64 hex digits "
                              "or a passphrase") from err
    if not text:
        raise SigningKeyError(f"signing key file {path}: empty")
    if len(text) == 64:
        try:
            return bytes.fromhex(text)
        except ValueError:
            pass
    return hashlib.sha256(text.encode("utf-8")).digest()


@dataclass
class RxCounters:
    """What the parser saw.  ``packets`` are good MAVLink 2 messages handed on."""

    bytes: int = 0
    packets: int = 0
    bad_crc: int = 0
    bad_signature: int = 0
    bad_framing: int = 0
    unknown_id: int = 0
    mavlink1: int = 0
    truncated: int = 0
    dropped_budget: int = 0
    parser_errors: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class _Sink:
    """File-like object for pymavlink: every ``write`` goes to the current transport."""

    def __init__(self) -> None:
        self.target: Callable[[bytes], None] | None = None
        self.bytes_unsent = 0

    def write(self, data: bytes) -> None:
        if self.target is None:
            self.bytes_unsent += len(data)
        else:
            self.target(bytes(data))


class Codec:
    """One MAVLink 2 endpoint identity: our ids, the sequence counter, signing, the parser."""

    def __init__(self, system_id: int, component_id: int) -> None:
        self._sink = _Sink()
        self.mav = mavlink2.MAVLink(self._sink, srcSystem=system_id, srcComponent=component_id)
        self.mav.robust_parsing = True
        self.rx = RxCounters()
        self._allowed_unsigned: frozenset[int] = frozenset()

    def set_writer(self, write: Callable[[bytes], None] | None) -> None:
        self._sink.target = write

    @property
    def system_id(self) -> int:
        return int(self.mav.srcSystem)

    @system_id.setter
    def system_id(self, value: int) -> None:
        self.mav.srcSystem = value

    def reset_sequence(self) -> None:
        """Start again at sequence 0 (a rebooted autopilot does this)."""
        self.mav.seq = 0

    def enable_signing(self, key: bytes, link_id: int, allow_unsigned: Iterable[str]) -> None:
        """Sign everything we send; accept unsigned incoming only for ``allow_unsigned`` names."""
        if len(key) != 32:
            raise SigningKeyError(f"signing key: expected 32 bytes, got {len(key)}")
        ids = set()
        for name in allow_unsigned:
            msg_id = getattr(mavlink2, f"MAVLINK_MSG_ID_{name.upper()}", None)
            if msg_id is None:
                raise SigningKeyError(f"allow_unsigned: unknown message name {name!r}")
            ids.add(int(msg_id))
        self._allowed_unsigned = frozenset(ids)
        s = self.mav.signing
        s.secret_key = key
        s.link_id = link_id
        s.timestamp = signing_timestamp_now()
        s.sign_outgoing = True
        s.allow_unsigned_callback = self._allow_unsigned
        if not getattr(self, "_guarded", False):
            self._pymavlink_check = self.mav.check_signature
            self.mav.check_signature = self._check_signature
            self._guarded = True

    def _check_signature(self, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        """pymavlink's check, but a message whose signature is wrong cannot move its stream's
        replay timestamp: pymavlink records the timestamp *before* verifying the signature, so
        one forged message with a far-future stamp (any key) would make every genuine message
        of that stream "old" -- a lock-out found by sitl_tests/test_mavlink_faults.py."""
        stamps = self.mav.signing.stream_timestamps
        key = (msgbuf[-13], src_system, src_component)
        had, before = key in stamps, stamps.get(key)
        ok = bool(self._pymavlink_check(msgbuf, src_system, src_component))
        if not ok:
            if had:
                stamps[key] = before
            else:
                stamps.pop(key, None)
        return ok

    def _allow_unsigned(self, _mav: Any, msg_id: int) -> bool:
        return msg_id in self._allowed_unsigned

    @property
    def signing(self) -> bool:
        return self.mav.signing.secret_key is not None

    def feed(self, data: bytes, datagram: bool) -> list[MAVLinkMessage]:
        """Parse ``data``; return the good MAVLink 2 messages, count everything else.

        With ``datagram`` true the bytes are one whole UDP datagram: whatever is left in the
        parser afterwards is a truncated packet and is discarded, so it cannot swallow the
        start of the next datagram.
        """
        self.rx.bytes += len(data)
        out: list[MAVLinkMessage] = []
        try:
            msgs = self.mav.parse_buffer(data) or []
        except Exception:  # pymavlink must never take the link down
            self.rx.parser_errors += 1
            self._reset_parser()
            return out
        for m in msgs:
            self._classify(m, out)
        if datagram and len(self.mav.buf) - self.mav.buf_index > 0:
            self.rx.truncated += 1
            self._reset_parser()
        return out

    def _classify(self, m: MAVLinkMessage, out: list[MAVLinkMessage]) -> None:
        kind = m.get_type()
        if kind == "BAD_DATA":
            reason = str(getattr(m, "reason", ""))
            if "CRC" in reason:
                self.rx.bad_crc += 1
            elif "signature" in reason:
                self.rx.bad_signature += 1
            else:
                self.rx.bad_framing += 1
        elif kind.startswith("UNKNOWN_"):
            self.rx.unknown_id += 1
        elif m.get_header() is None or m._msgbuf[0] != mavlink2.PROTOCOL_MARKER_V2:
            self.rx.mavlink1 += 1  # MAVLink 2 only: a v1 frame cannot be signed
        else:
            self.rx.packets += 1
            out.append(m)

    def _reset_parser(self) -> None:
        self.mav.buf = bytearray()
        self.mav.buf_index = 0
        self.mav.expected_length = mavlink2.HEADER_LEN_V1 + 2
