"""``companion demo``: the embedded default -- simulated camera, fake autopilot, Zenoh."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys

from companion.cli import positive_seconds
from companion.config_checks import check_flightlog_dir
from companion.settings import SIM_LAYERS, Settings


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion demo``."""
    parser = sub.add_parser(
        "demo", help="run everything on this machine: simulated flight, fake autopilot, Zenoh",
        description="Fly a simulated scenario over config/landmarks.geojson with the fake "
        "autopilot on UDP loopback and monitoring on Zenoh; print a summary against truth.",
    )
    parser.add_argument("--seconds", type=positive_seconds,
                        default=20.0, help="flight time (default 20)")
    parser.add_argument("--scenario", default="survey",
                        help="scenario name in config/scenarios/ or a TOML file (default survey)")
    parser.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    parser.add_argument("--attitude-error", action="store_true",
                        help="the fake autopilot's attitude carries a real EKF's error (1 deg "
                        "roll/pitch, 3 deg yaw, 1 deg/min yaw drift); default: the exact one")
    parser.add_argument("--deployment-prior", action="store_true",
                        help="state the autopilot's attitude to the pose solver with the "
                        "configured sigmas (pose.attitude_*_sigma_deg, a few degrees); "
                        "default: the fake autopilot's real error (0.2 / 1 deg when exact)")
    parser.set_defaults(handler=run, shipped=SIM_LAYERS)


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Run the demo with a live progress line on a terminal."""
    check_flightlog_dir(settings)
    live = sys.stderr.isatty() and not args.json

    def progress(line: str) -> None:
        sys.stderr.write("\r" + line)
        sys.stderr.flush()

    from companion.demo import print_summary, run_demo  # the simulator: only for the demo

    result = asyncio.run(run_demo(settings, args.scenario, args.seconds,
                                  progress if live else None, args.attitude_error,
                                  args.deployment_prior))
    if live:
        sys.stderr.write("\n")
    if args.json:
        print(json.dumps(result))
    else:
        print_summary(result)
    return 0
