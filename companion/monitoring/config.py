"""Monitoring configuration and the Zenoh session it opens."""

from __future__ import annotations

import dataclasses
import json
import socket
from dataclasses import dataclass, field
from typing import Literal

import zenoh

from companion.errors import LinkError

ZenohMode = Literal["peer", "client", "router"]

#: Where ``companion demo`` and the monitors meet on one machine when no endpoint is
#: configured (docs/monitoring.md): the demo listens here (or, when the port is taken,
#: e.g. by ``companion router``, connects to it); ``monitor`` and ``dashboard`` connect here.
LOCAL_ENDPOINT = "tcp/127.0.0.1:7447"


@dataclass(frozen=True)
class MonitorConfig:
    """How this process joins the Zenoh network, and how much it publishes.

    Multicast scouting is off by default: a companion talks to the endpoints it is given
    (``tcp/HOST:PORT``), which is predictable on a vehicle's network and safe in tests.
    """

    enabled: bool = True
    mode: ZenohMode = "peer"
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    status_rate_hz: float = field(default=1.0, metadata={"gt": 0, "le": 10})
    preview_rate_hz: float = field(default=2.0, metadata={"gt": 0, "le": 2})
    preview_width_px: int = field(default=320, metadata={"ge": 64, "le": 1280})
    preview_jpeg_quality: int = field(default=70, metadata={"ge": 10, "le": 95})


def zenoh_config(mode: ZenohMode, listen: tuple[str, ...] = (), connect: tuple[str, ...] = (),
                 multicast_scouting: bool = False) -> zenoh.Config:
    """A Zenoh configuration with explicit endpoints (JSON5 values, as zenoh wants)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(multicast_scouting))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    return conf


def open_session(cfg: MonitorConfig) -> zenoh.Session:
    """Open a Zenoh session for ``cfg``; failure is a one-line LinkError.

    In ``client`` mode Zenoh fails at once when no endpoint answers; ``peer`` mode keeps
    retrying its ``connect`` endpoints in the background.
    """
    try:
        return zenoh.open(zenoh_config(cfg.mode, cfg.listen, cfg.connect,
                                       cfg.multicast_scouting))
    except zenoh.ZError as err:
        where = ", ".join(cfg.listen + cfg.connect) or "no endpoints"
        reason = str(err).split("  at ", 1)[0].rstrip(". ")
        raise LinkError(f"zenoh ({cfg.mode}, {where}): {reason}") from None


def _port_free(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def local_meeting(cfg: MonitorConfig) -> MonitorConfig:
    """``cfg`` for a process that publishes (the demo): unchanged when it names endpoints,
    else listening on :data:`LOCAL_ENDPOINT`, or connected to it when the port is taken."""
    if cfg.listen or cfg.connect:
        return cfg
    host, _, port = LOCAL_ENDPOINT.removeprefix("tcp/").rpartition(":")
    if _port_free(host, int(port)):
        return dataclasses.replace(cfg, listen=(LOCAL_ENDPOINT,))
    return dataclasses.replace(cfg, connect=(LOCAL_ENDPOINT,))


def watcher_endpoints(given: list[str] | None, cfg: MonitorConfig) -> tuple[str, ...]:
    """Where ``monitor`` and ``dashboard`` connect: ``--connect``, else
    ``monitor.connect``, else :data:`LOCAL_ENDPOINT` (the demo on this machine)."""
    return tuple(given or cfg.connect or (LOCAL_ENDPOINT,))
