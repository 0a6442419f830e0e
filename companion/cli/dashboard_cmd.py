"""``companion dashboard``: serve the read-only web page of the fleet."""

from __future__ import annotations

import argparse
import dataclasses
import ipaddress
import logging
import os

from companion.errors import ConfigError
from companion.extras import require
from companion.monitoring import MonitorWatcher
from companion.monitoring.config import LOCAL_ENDPOINT, watcher_endpoints
from companion.settings import Settings

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion dashboard``."""
    parser = sub.add_parser(
        "dashboard", help="serve a read-only web page: preview, status, fixes, landmark map",
        description="Serve the dashboard over HTTP, fed by the Zenoh monitoring keys.  "
        "Binds to 127.0.0.1; another address needs --token (or LMC_DASHBOARD_TOKEN).",
    )
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default loopback)")
    parser.add_argument("--port", type=int, default=8321)
    parser.add_argument("--token", help="required for a non-loopback address; requests carry "
                        "it as 'Authorization: Bearer TOKEN' or '?token=TOKEN'")
    parser.add_argument("--connect", action="append", metavar="ENDPOINT",
                        help="Zenoh endpoint of the vehicle or router (default monitor.connect, "
                        f"else {LOCAL_ENDPOINT} where companion demo listens)")
    parser.set_defaults(handler=run)


def is_loopback(host: str) -> bool:
    """True for localhost and loopback addresses."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Serve until Ctrl-C or SIGTERM."""
    token = args.token or os.environ.get("LMC_DASHBOARD_TOKEN") or None
    if not is_loopback(args.host) and not token:
        raise ConfigError(f"dashboard: binding to {args.host} needs --token (or "
                          "LMC_DASHBOARD_TOKEN): the page must not be open to the network")
    uvicorn = require("uvicorn", "dashboard", "companion dashboard")
    require("starlette", "dashboard", "companion dashboard")
    from companion.dashboard.server import create_app  # the extra is there: load it now

    connect = watcher_endpoints(args.connect, settings.monitor)
    # peer mode keeps retrying an endpoint that is down (client mode gives up at once)
    cfg = dataclasses.replace(settings.monitor, mode="peer", connect=connect)
    watcher = MonitorWatcher(cfg)
    try:
        print(f"dashboard on http://{args.host}:{args.port}/", flush=True)
        uvicorn.run(create_app(watcher, token), host=args.host, port=args.port,
                    log_level="warning", access_log=False)
    finally:
        watcher.close()
    return 0
