"""``companion replay``: the whole companion on a recorded stream, scored against its truth."""

from __future__ import annotations

import argparse
import asyncio
import json
from pathlib import Path

from companion.config_checks import check_flightlog_dir
from companion.errors import InputError
from companion.settings import Settings


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion replay``."""
    parser = sub.add_parser(
        "replay", help="replay a recorded stream through the whole companion and score it",
        description="Run the companion (perception, bridge, flight log, Zenoh when "
        "configured) on a recorded stream folder with the fake autopilot replaying the "
        "stream's telemetry, on one clock, and print the fixes against the stream's "
        "truth_pose.csv (docs/replay.md).",
    )
    parser.add_argument("stream", type=Path, metavar="STREAM", help="a recorded stream folder")
    parser.add_argument("--fast", action="store_true",
                        help="frames as fast as they are processed, none dropped (default: "
                        "in real time, dropping what the processing cannot keep up with)")
    parser.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    parser.add_argument("--attitude-seed", type=int, default=0, metavar="N",
                        help="a stream without recorded telemetry: the seed of the simulated "
                        "autopilot's attitude error added to truth_pose.csv (default 0)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Replay, then print the summary."""
    from companion.replay import run_replay
    from companion.replay_score import print_replay

    if args.attitude_seed < 0:
        raise InputError(f"--attitude-seed: expected an integer >= 0, got {args.attitude_seed}")
    if not (args.stream / "stream.toml").is_file():
        raise InputError(f"{args.stream}: not a recorded stream folder (no stream.toml)")
    check_flightlog_dir(settings)
    result = asyncio.run(run_replay(settings, args.stream, args.fast,
                                     args.attitude_seed))
    if args.json:
        print(json.dumps(result))
    else:
        print_replay(result)
    return 0
