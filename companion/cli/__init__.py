"""The ``companion`` command line: global options, then one subcommand.

A subcommand is a module ``companion/cli/<name>_cmd.py`` with
``register(sub)`` (adds its parser and ``set_defaults(handler=run)``) and
``run(args, settings) -> int``.  It is listed in :data:`COMMAND_MODULES` only once it does
its job: ``--help`` shows exactly what exists.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from companion import __version__
from companion.errors import CompanionError
from companion.logs import setup_logging
from companion.settings import load_settings

#: Subcommand modules, in the order ``--help`` lists them.
COMMAND_MODULES: tuple[str, ...] = (
    "demo_cmd",
    "run_cmd",
    "monitor_cmd",
    "dashboard_cmd",
    "router_cmd",
    "log_cmd",
    "config_cmd",
    "synth_cmd",
    "record_cmd",
    "fake_autopilot_cmd",
    "autopilot_cmd",
    "landmarks_cmd",
    "eval_cmd",
)

log = logging.getLogger("companion")


def _add_common(parser: argparse.ArgumentParser, suppress: bool) -> None:
    """Options accepted before or after the subcommand name."""

    def default(value: object) -> object:
        return argparse.SUPPRESS if suppress else value

    group = parser.add_argument_group("configuration and logging")
    group.add_argument("--config", action="append", type=Path, default=default([]),
                       metavar="FILE", help="TOML file layered over the defaults (repeatable)")
    group.add_argument("--set", action="append", default=default([]), dest="sets",
                       metavar="SECTION.KEY=VALUE", help="override one setting (repeatable)")
    group.add_argument("--log-format", choices=("text", "json"), default=default(None),
                       help="log as readable text or JSON lines (default: logging.format)")
    group.add_argument("--log-level", choices=("debug", "info", "warning", "error"),
                       default=default(None), help="default: logging.level")


def build_parser() -> argparse.ArgumentParser:
    """The full parser with every registered subcommand."""
    parser = argparse.ArgumentParser(
        prog="companion",
        description="landmark-companion: track known landmarks, send vision position fixes "
        "to ArduPilot or PX4 over MAVLink, watch it all over Zenoh.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    _add_common(parser, suppress=False)
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", dest="command")
    for name in COMMAND_MODULES:
        module = importlib.import_module(f"companion.cli.{name}")
        before = set(sub.choices)
        module.register(sub)
        for added in set(sub.choices) - before:
            _add_common(sub.choices[added], suppress=True)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``companion`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:
        parser.print_help()
        return 2
    setup_logging(args.log_format or "text", args.log_level or "info")
    try:
        settings = load_settings(args.config, args.sets)
        setup_logging(args.log_format or settings.logging.format,
                      args.log_level or settings.logging.level)
        return int(args.handler(args, settings))
    except CompanionError as err:
        print(str(err), file=sys.stderr)
        return err.exit_status
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # e.g. `companion config | head`: not an error
        sys.stdout = open(os.devnull, "w")
        return 0
