"""``companion router``: a Zenoh router where a fleet's companions and monitors meet."""

from __future__ import annotations

import argparse
import logging
import signal
import threading

import zenoh

from companion.cli import positive_seconds
from companion.errors import ConfigError, note_stop_signal
from companion.monitoring.config import zenoh_config
from companion.settings import Settings

log = logging.getLogger(__name__)
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion router``."""
    parser = sub.add_parser(
        "router", help="run a Zenoh router for a fleet (companions and monitors connect to it)",
        description="Run a Zenoh session in router mode until SIGINT/SIGTERM.  Companions "
        "(monitor.mode = \"client\" or \"peer\" with monitor.connect) and monitors "
        "(--connect) meet through it.",
    )
    parser.add_argument("--listen", action="append", metavar="ENDPOINT",
                        help=f"endpoint to listen on (repeatable; default {DEFAULT_ENDPOINT} "
                        "or monitor.listen)")
    parser.add_argument("--seconds", type=positive_seconds, help="stop after this many seconds")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Serve until a signal (or --seconds)."""
    listen = tuple(args.listen or settings.monitor.listen or (DEFAULT_ENDPOINT,))
    try:
        session = zenoh.open(zenoh_config("router", listen, settings.monitor.connect,
                                          settings.monitor.multicast_scouting))
    except zenoh.ZError as err:
        raise ConfigError(f"router: cannot listen on {', '.join(listen)}: {err}") from None
    stop = threading.Event()

    def on_signal(signum: int, _frame: object) -> None:
        note_stop_signal(signum)  # a clean stop; the CLI exits 128 + signum
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    log.info("zenoh router listening on %s", ", ".join(listen))
    print(f"router listening on {', '.join(listen)}", flush=True)
    stop.wait(args.seconds)
    session.close()
    log.info("router stopped")
    return 0
