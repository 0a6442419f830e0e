"""``companion monitor``: a live terminal view of every companion on the Zenoh network."""

from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from companion.cli import positive_seconds
from companion.errors import InputError, Interrupted, note_stop_signal
from companion.monitoring import FleetView, MonitorWatcher
from companion.monitoring.config import LOCAL_ENDPOINT, watcher_endpoints
from companion.monitoring.render import render_fleet
from companion.settings import Settings


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion monitor``."""
    parser = sub.add_parser(
        "monitor", help="watch companions live over Zenoh (status, pose, tracks, events)",
        description="Subscribe to companion/<vehicle>/* and show every vehicle's state.",
    )
    parser.add_argument("--vehicle", default="*", metavar="ID", help="only this vehicle")
    parser.add_argument("--connect", action="append", metavar="ENDPOINT",
                        help="Zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 "
                        f"(repeatable; default: monitor.connect, else {LOCAL_ENDPOINT} where "
                        "companion demo listens)")
    parser.add_argument("--seconds", type=positive_seconds, help="stop after this many seconds")
    parser.add_argument("--snapshot", type=Path, metavar="FILE.png",
                        help="save the latest preview as PNG and exit")
    parser.add_argument("--json", action="store_true",
                        help="at the end, print what was seen as one JSON object")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Watch until Ctrl-C, --seconds, or a snapshot is saved."""
    # peer mode: it keeps retrying an endpoint that is down, so the view shows stale
    # data with its age instead of failing (client mode gives up at once)
    cfg = dataclasses.replace(settings.monitor, mode="peer",
                              connect=watcher_endpoints(args.connect, settings.monitor))
    watcher = MonitorWatcher(cfg, args.vehicle)
    try:
        if args.snapshot:
            return _snapshot(watcher, args.snapshot, args.seconds or 10.0)
        view = _watch(watcher, args.seconds, live=sys.stdout.isatty() and not args.json)
        if args.json:
            print(json.dumps(_as_json(view), default=str))
        return 0
    finally:
        watcher.close()


def _watch(watcher: MonitorWatcher, seconds: float | None, live: bool) -> FleetView:
    deadline = None if seconds is None else time.monotonic() + seconds
    view = watcher.snapshot()
    try:
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.5)
            view = watcher.snapshot()
            if live:
                sys.stdout.write("\x1b[H\x1b[2J" + render_fleet(view) + "\n")
                sys.stdout.flush()
    except KeyboardInterrupt:
        note_stop_signal(signal.SIGINT)  # show the view, then exit 130
    except Interrupted as stop:
        note_stop_signal(stop.signum)  # SIGTERM: show the view, then exit 143
    if not live:
        print(render_fleet(view), file=sys.stderr)
    return view


def _snapshot(watcher: MonitorWatcher, path: Path, timeout_s: float) -> int:
    if not watcher.wait_for("preview", timeout_s=timeout_s):
        raise InputError(f"no preview received within {timeout_s:.0f} s")
    view = watcher.snapshot()
    jpeg = next(v.preview_jpeg for v in view.vehicles.values() if v.preview_jpeg)
    image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise InputError("the preview received is not a readable JPEG")
    if not cv2.imwrite(str(path), image):
        raise InputError(f"{path}: cannot write the snapshot")
    print(f"saved {path} ({image.shape[1]}x{image.shape[0]})")
    return 0


def _as_json(view: FleetView) -> dict[str, object]:
    return {
        "malformed": view.malformed,
        "vehicles": {
            vid: {"latest": dict(v.latest), "counts": dict(v.counts),
                  "events": list(v.events), "preview_bytes": len(v.preview_jpeg or b""),
                  "age_s": {t: round(v.age_s(t) or 0.0, 3) for t in v.received_s}}
            for vid, v in view.vehicles.items()
        },
    }
