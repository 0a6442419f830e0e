"""``companion check``: the preflight a user runs before every flight (docs/deploy.md)."""

from __future__ import annotations

import argparse
import asyncio

from companion.preflight import run_checks
from companion.settings import Settings


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion check``."""
    parser = sub.add_parser(
        "check", help="preflight: camera, camera file, landmarks, link -- one line each",
        description="Open the camera and compare its frames with the camera file, check the "
        "intrinsics, that every landmark of the map has a reference image the matcher "
        "accepts, and that the autopilot answers.  One line per check (pass, warn or FAIL "
        "and the reason); exit status 1 when any check fails.")
    parser.add_argument("--link-timeout", type=float, default=5.0, metavar="S",
                        help="seconds to wait for the autopilot's heartbeat (default 5)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Run every check and print them."""
    checks = asyncio.run(run_checks(settings, args.link_timeout))
    for check in checks:
        print(check.line(), flush=True)
    failed = [c.name for c in checks if c.verdict == "fail"]
    print(f"{len(checks) - len(failed)} of {len(checks)} checks passed"
          + (f"; failed: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0
