"""Connection strings and the asyncio byte transports behind them.

Five transports: ``udpin`` (bind HOST:PORT, answer the last sender), ``udpout`` (send to
HOST:PORT), ``tcp`` (connect; reconnected by the link), ``tcpin`` (listen for one client at a
time, the newest wins) and ``serial`` (a tty in raw mode).  :func:`parse_endpoint` accepts
the spellings users bring from pymavlink's ``mavutil``, MAVProxy, MAVSDK and MAVROS; the
table (spelling -> meaning -> what is opened) with its sources is in docs/mavlink.md.  The
transports only move bytes; MAVLink framing lives in :mod:`mavlink_bridge.codec`.
Everything runs on the event loop; nothing blocks it (serial uses ``add_reader`` on a
non-blocking file descriptor, writes that would block are dropped and counted).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import termios
import tty
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from mavlink_bridge.errors import EndpointError, LinkOpenError

EndpointKind = Literal["udpin", "udpout", "tcp", "tcpin", "serial"]
DataCallback = Callable[[bytes], None]

#: pymavlink mavutil's default baud rate (``mavlink_connection(device, baud=115200)``),
#: used when a serial spelling gives none.
DEFAULT_BAUD = 115200
#: ``KIND:...`` spellings: mavutil (``udp:`` listens, like ``udpin:``; mavutil.py
#: mavlink_connection passes ``input=True`` by default), MAVProxy (``tcpout:``) and ours
#: (``serial:DEVICE:BAUD``).
_COLON_KINDS: dict[str, EndpointKind] = {
    "udpin": "udpin", "udp": "udpin", "udpout": "udpout", "tcp": "tcp", "tcpout": "tcp",
    "tcpin": "tcpin", "serial": "serial",
}
#: ``SCHEME://...`` spellings: MAVSDK (src/mavsdk/core/cli_arg.cpp; ``udp://`` and ``tcp://``
#: are its legacy forms, resolved by host below) and MAVROS's ``tcp-l://`` and ``serial://``.
_URL_KINDS: dict[str, EndpointKind] = {
    "udpin": "udpin", "udpout": "udpout", "tcpin": "tcpin", "tcpout": "tcp", "tcp-l": "tcpin",
    "serial": "serial",
}
_UNSUPPORTED = {
    "udpbcast": "UDP broadcast", "mcast": "UDP multicast", "uds": "Unix sockets",
    "unix": "Unix sockets", "ws": "WebSocket", "wss": "WebSocket", "wsserver": "WebSocket",
    "serial_flowcontrol": "serial hardware flow control",
    "serial-hwfc": "serial hardware flow control", "udp-b": "UDP broadcast",
    "udp-pb": "UDP broadcast", "csv": "log files",
}
_LISTEN_ANY = ("", "0.0.0.0", "::")
_SHAPES = ("udpin:|udpout:|tcp:|tcpin:HOST:PORT, udpin://|udpout://|tcp://|tcpin://HOST:PORT, "
           "bare HOST:PORT (listen), serial:DEVICE:BAUD, serial://DEVICE:BAUD or DEVICE[,:]BAUD")


@dataclass(frozen=True)
class Endpoint:
    """A parsed connection string; ``host``/``port`` for sockets, ``device``/``baud`` for serial."""

    kind: EndpointKind
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0

    @property
    def datagram(self) -> bool:
        """True when each read is one whole datagram (UDP): leftovers are truncated packets."""
        return self.kind in ("udpin", "udpout")

    def __str__(self) -> str:
        if self.kind == "serial":
            return f"serial:{self.device}:{self.baud}"
        return f"{self.kind}:{self.host}:{self.port}"


def parse_endpoint(spec: str) -> Endpoint:
    """Parse any spelling of docs/mavlink.md's table; raise :class:`EndpointError` (one line,
    with the string) for anything else."""
    text = spec.strip()
    scheme, sep, rest = text.partition("://")
    if sep:
        return _parse_url(spec, scheme.lower(), rest)
    head, sep, rest = text.partition(":")
    if head.lower() in _UNSUPPORTED:
        raise EndpointError(f"endpoint {spec!r}: {_UNSUPPORTED[head.lower()]} is not supported")
    if sep and head.lower() in _COLON_KINDS:
        kind = _COLON_KINDS[head.lower()]
        return _serial(spec, rest) if kind == "serial" else _socket(spec, kind, rest)
    if text.startswith("/") or re.fullmatch(r"COM\d+([,:]\d+)?", text):
        return _serial(spec, text)  # mavutil/MAVProxy DEVICE[,BAUD], MAVROS DEVICE[:BAUD]
    if re.fullmatch(r"([A-Za-z0-9.-]*|\[[0-9A-Fa-f:.]+\]):\d+", text):
        return _socket(spec, "udpin", text)  # mavutil: a bare HOST:PORT listens on UDP
    raise EndpointError(f"endpoint {spec!r}: expected {_SHAPES}")


def _parse_url(spec: str, scheme: str, rest: str) -> Endpoint:
    if scheme in _UNSUPPORTED:
        raise EndpointError(f"endpoint {spec!r}: {_UNSUPPORTED[scheme]} is not supported")
    if "@" in rest:
        raise EndpointError(f"endpoint {spec!r}: MAVROS's BIND@REMOTE form is not supported; "
                            "use udpin://BIND:PORT or udpout://REMOTE:PORT")
    if scheme in ("udp", "tcp"):  # MAVSDK's legacy forms: no host or 0.0.0.0 listens
        host = rest.rpartition(":")[0].strip("[]")
        listen = host in _LISTEN_ANY
        kind: EndpointKind = ("udpin" if listen else "udpout") if scheme == "udp" else (
            "tcpin" if listen else "tcp")
        return _socket(spec, kind, rest)
    if scheme not in _URL_KINDS:
        raise EndpointError(f"endpoint {spec!r}: unknown scheme {scheme!r}; expected {_SHAPES}")
    kind = _URL_KINDS[scheme]
    return _serial(spec, rest) if kind == "serial" else _socket(spec, kind, rest)


def _socket(spec: str, kind: EndpointKind, rest: str) -> Endpoint:
    host, sep, number = rest.rpartition(":")
    if not sep or not number.isdigit():
        raise EndpointError(f"endpoint {spec!r}: expected {kind}:HOST:PORT")
    port = int(number)
    if port > 65535:
        raise EndpointError(f"endpoint {spec!r}: port must be 0..65535")
    host = host.strip("[]")
    if not host:
        if kind in ("udpout", "tcp"):
            raise EndpointError(f"endpoint {spec!r}: {kind} needs a host to send to")
        host = "0.0.0.0"  # a listener without a host listens on every interface
    return Endpoint(kind=kind, host=host, port=port)


def _serial(spec: str, rest: str) -> Endpoint:
    device, baud_text = rest, ""
    for mark in (",", ":"):
        head, sep, tail = rest.rpartition(mark)
        if sep and tail.isdigit():
            device, baud_text = head, tail
            break
    if not device or device.endswith((",", ":")):
        raise EndpointError(f"endpoint {spec!r}: expected a serial DEVICE and a BAUD rate")
    baud = int(baud_text) if baud_text else DEFAULT_BAUD
    if baud <= 0 or getattr(termios, f"B{baud}", None) is None:  # B0 means "hang up"
        raise EndpointError(f"endpoint {spec!r}: unsupported baud rate {baud}")
    return Endpoint(kind="serial", device=device, baud=baud)


class Connection:
    """An open transport.  ``write`` never blocks; ``closed`` resolves when it dies."""

    def __init__(self, endpoint: Endpoint) -> None:
        self.endpoint = endpoint
        self.closed: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.bytes_dropped = 0
        #: bytes handed to the datagram socket (UDP; what a loopback peer will read), and
        #: bytes read from it
        self.bytes_written = 0
        self.bytes_read = 0
        self.local_port = 0

    def write(self, data: bytes) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def close(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _mark_closed(self) -> None:
        if not self.closed.done():
            self.closed.set_result(None)


class _UdpProtocol(asyncio.DatagramProtocol):
    def __init__(self, conn: UdpConnection, on_data: DataCallback) -> None:
        self._conn = conn
        self._on_data = on_data

    def datagram_received(self, data: bytes, addr: tuple[str | object, ...]) -> None:
        if self._conn.endpoint.kind == "udpin":
            self._conn.peer = addr  # answer whoever spoke last, like mavutil
        self._conn.bytes_read += len(data)
        self._on_data(data)

    def error_received(self, exc: Exception) -> None:
        # ICMP "port unreachable" while the peer is not up yet: not fatal for UDP.
        self._conn.send_errors += 1

    def connection_lost(self, exc: Exception | None) -> None:
        self._conn._mark_closed()


class UdpConnection(Connection):
    """udpin (bind, reply to last sender) or udpout (fixed peer)."""

    def __init__(self, endpoint: Endpoint) -> None:
        super().__init__(endpoint)
        self.transport: asyncio.DatagramTransport | None = None
        self.peer: tuple[str | object, ...] | None = None
        self.send_errors = 0

    def write(self, data: bytes) -> None:
        if self.transport is None or self.transport.is_closing():
            self.bytes_dropped += len(data)
            return
        if self.endpoint.kind == "udpout":
            self.transport.sendto(data)
            self.bytes_written += len(data)
        elif self.peer is not None:
            self.transport.sendto(data, self.peer)
            self.bytes_written += len(data)
        else:
            self.bytes_dropped += len(data)  # nobody has spoken to us yet

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()
        self._mark_closed()


class _StreamProtocol(asyncio.Protocol):
    def __init__(self, conn: StreamConnection, on_data: DataCallback) -> None:
        self._conn = conn
        self._on_data = on_data

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        previous = self._conn.transport
        self._conn.transport = transport
        if previous is not None and previous is not transport:
            previous.close()  # tcpin: the newest client wins

    def data_received(self, data: bytes) -> None:
        self._on_data(data)

    def connection_lost(self, exc: Exception | None) -> None:
        if self._conn.endpoint.kind == "tcp":
            self._conn._mark_closed()


class StreamConnection(Connection):
    """tcp (client: closes with the socket) or tcpin (server: lives until closed)."""

    def __init__(self, endpoint: Endpoint) -> None:
        super().__init__(endpoint)
        self.transport: asyncio.Transport | None = None
        self.server: asyncio.Server | None = None

    def write(self, data: bytes) -> None:
        t = self.transport
        if t is None or t.is_closing() or t.get_write_buffer_size() > 65536:
            self.bytes_dropped += len(data)
            return
        t.write(data)

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()
        if self.server is not None:
            self.server.close()
        self._mark_closed()


class SerialConnection(Connection):
    """A tty opened raw and non-blocking, read with ``loop.add_reader``."""

    def __init__(self, endpoint: Endpoint, on_data: DataCallback) -> None:
        super().__init__(endpoint)
        self._on_data = on_data
        self._loop = asyncio.get_running_loop()
        try:
            self.fd = os.open(endpoint.device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError as err:
            raise LinkOpenError(f"serial {endpoint.device}: {err.strerror}") from err
        try:
            _configure_tty(self.fd, endpoint.baud)
        except (termios.error, OSError, ValueError) as err:
            os.close(self.fd)
            raise LinkOpenError(f"serial {endpoint.device}: cannot configure: {err}") from err
        self._loop.add_reader(self.fd, self._readable)

    def _readable(self) -> None:
        try:
            data = os.read(self.fd, 4096)
        except BlockingIOError:
            return
        except OSError:
            self.close()
            return
        if not data:
            self.close()
            return
        self._on_data(data)

    def write(self, data: bytes) -> None:
        if self.closed.done():
            self.bytes_dropped += len(data)
            return
        try:
            sent = os.write(self.fd, data)
        except BlockingIOError:
            sent = 0
        except OSError:
            self.close()
            return
        self.bytes_dropped += len(data) - sent

    def close(self) -> None:
        if not self.closed.done():
            self._loop.remove_reader(self.fd)
            with contextlib.suppress(OSError):
                os.close(self.fd)
        self._mark_closed()


def _configure_tty(fd: int, baud: int) -> None:
    tty.setraw(fd)
    attrs = termios.tcgetattr(fd)
    speed = getattr(termios, f"B{baud}", None)
    if speed is None:
        raise ValueError(f"unsupported baud rate {baud}")
    attrs[4] = attrs[5] = speed
    termios.tcsetattr(fd, termios.TCSANOW, attrs)


async def open_connection(endpoint: Endpoint, on_data: DataCallback) -> Connection:
    """Open ``endpoint``; bytes arrive through ``on_data`` on the loop thread."""
    loop = asyncio.get_running_loop()
    try:
        if endpoint.datagram:
            udp = UdpConnection(endpoint)
            if endpoint.kind == "udpin":
                transport, _ = await loop.create_datagram_endpoint(
                    lambda: _UdpProtocol(udp, on_data), local_addr=(endpoint.host, endpoint.port)
                )
            else:
                transport, _ = await loop.create_datagram_endpoint(
                    lambda: _UdpProtocol(udp, on_data), remote_addr=(endpoint.host, endpoint.port)
                )
            udp.transport = transport
            udp.local_port = transport.get_extra_info("sockname")[1]
            return udp
        if endpoint.kind in ("tcp", "tcpin"):
            tcp = StreamConnection(endpoint)
            if endpoint.kind == "tcp":
                await loop.create_connection(
                    lambda: _StreamProtocol(tcp, on_data), endpoint.host, endpoint.port
                )
            else:
                tcp.server = await loop.create_server(
                    lambda: _StreamProtocol(tcp, on_data), endpoint.host, endpoint.port
                )
                tcp.local_port = tcp.server.sockets[0].getsockname()[1]
            return tcp
        return SerialConnection(endpoint, on_data)
    except OSError as err:
        raise LinkOpenError(f"{endpoint}: {err.strerror or err}") from err
