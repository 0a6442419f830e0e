"""``companion fake-autopilot``: run the scripted fake autopilot (ArduPilot or PX4 rules).

It flies the default hover-then-circle trajectory, streams telemetry, answers commands,
judges every vision message like the real autopilot would, and on exit prints (or writes) a
JSON summary of what it received.  Point ``companion run`` (``mavlink.endpoint``) at it.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import signal
import sys
from pathlib import Path
from typing import Any

from companion.cli import positive_seconds
from companion.errors import ConfigError, InputError, LinkError, note_stop_signal
from companion.settings import Settings
from mavlink_bridge.codec import load_signing_key
from mavlink_bridge.errors import EndpointError, LinkOpenError, SigningKeyError
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion fake-autopilot``."""
    parser = sub.add_parser(
        "fake-autopilot", help="run a scripted fake ArduPilot/PX4 that enforces their rules",
        description="A fake autopilot for tests and demos: telemetry out, vision messages "
        "judged and recorded; prints a JSON summary at the end.",
    )
    parser.add_argument("--profile", choices=("ardupilot", "px4"),
                        help="which autopilot's rules (default: vehicle.profile)")
    parser.add_argument("--endpoint", default="udpin:127.0.0.1:14550", metavar="SPEC",
                        help="udpin:|udpout:|tcp:|tcpin:HOST:PORT, serial:DEVICE:BAUD or "
                        "another spelling of docs/mavlink.md "
                        "(default: %(default)s, where the companion's default udpout points)")
    parser.add_argument("--seconds", type=positive_seconds,
                        metavar="S", help="stop after S seconds")
    parser.add_argument("--summary", type=Path, metavar="FILE.json",
                        help="write the JSON summary here instead of stdout")
    parser.add_argument("--sysid", type=int, default=1, help="system id (default: 1)")
    parser.add_argument("--origin-fail-first", type=int, default=0, metavar="N",
                        help="answer the first N origin commands FAILED, like SITL at boot")
    parser.add_argument("--signing-key", metavar="FILE",
                        help="enforce MAVLink signing with this key file")
    parser.add_argument("--timesync-samples", type=int, default=500, metavar="N",
                        help="PX4: good TIMESYNC round trips before stamps are converted")
    parser.set_defaults(handler=run)


def _config(args: argparse.Namespace, settings: Settings) -> FakeAutopilotConfig:
    if args.seconds is not None and args.seconds <= 0:
        raise ConfigError(f"--seconds: expected a number > 0, got {args.seconds}")
    if not 1 <= args.sysid <= 255:
        raise ConfigError(f"--sysid: expected 1..255, got {args.sysid}")
    try:
        key = load_signing_key(args.signing_key) if args.signing_key else None
    except SigningKeyError as err:
        raise InputError(str(err)) from err
    return FakeAutopilotConfig(
        profile=args.profile or settings.vehicle.profile, endpoint=args.endpoint,
        system_id=args.sysid, signing_key=key, origin_fail_first=max(0, args.origin_fail_first),
        timesync_samples_required=max(1, args.timesync_samples))


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Run until --seconds, Ctrl-C or SIGTERM; then emit the summary."""
    summary = asyncio.run(_run(_config(args, settings), args.seconds))
    text = json.dumps(summary, indent=2, default=str)
    if args.summary:
        try:
            args.summary.write_text(text + "\n", encoding="utf-8")
        except OSError as err:
            raise InputError(f"{args.summary}: cannot write: {err.strerror}") from err
        print(_one_line(summary), file=sys.stderr)
    else:
        print(text)
    return 0


async def _run(config: FakeAutopilotConfig, seconds: float | None) -> dict[str, Any]:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
            loop.add_signal_handler(sig, _stop_by_signal, stop, sig)
    try:
        ap = FakeAutopilot(config)
        await ap.start()
    except (EndpointError, LinkOpenError) as err:
        raise LinkError(f"fake-autopilot: {err}") from err
    try:
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), seconds)
    finally:
        await ap.stop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                loop.remove_signal_handler(sig)
    return ap.summary()


def _stop_by_signal(stop: asyncio.Event, signum: int) -> None:
    note_stop_signal(signum)  # summary first, then the CLI exits 128 + signum
    stop.set()


def _one_line(s: dict[str, Any]) -> str:
    return (f"fake-autopilot ({s['profile']}): {s['vision_accepted']}/{s['vision_received']} "
            f"vision messages fused, {s['companion_heartbeats']} companion heartbeats, "
            f"origin {'set' if s['origin'] else 'not set'}")
