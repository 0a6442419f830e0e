"""The ``companion`` command line: global options, then one subcommand.

A subcommand is a module ``companion/cli/<name>_cmd.py`` with
``register(sub)`` (adds its parser and ``set_defaults(handler=run)``; a command that flies
the simulator adds ``shipped=("sim",)``: the simulator's layer of defaults) and
``run(args, settings) -> int``.  It is listed in :data:`COMMAND_MODULES` only once it does
its job: ``--help`` shows exactly what exists.  A plug-in (:data:`PLUGINS`, the simulator's
source kinds) is named here and imported only when a source of its kind is opened.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import FrameType

from companion import __version__
from companion.errors import (
    EXIT_CONFIG,
    EXIT_OK,
    Interrupted,
    clear_stop_signals,
    failure_of,
    interrupted_status,
    stop_signal,
)
from companion.logs import setup_logging
from companion.settings import load_settings
from companion.sources.factory import plug_in_module

#: Subcommand modules, in the order ``--help`` lists them.
COMMAND_MODULES: tuple[str, ...] = (
    "demo_cmd",
    "run_cmd",
    "monitor_cmd",
    "dashboard_cmd",
    "router_cmd",
    "log_cmd",
    "config_cmd",
    "calibrate_cmd",
    "check_cmd",
    "synth_cmd",
    "record_cmd",
    "replay_cmd",
    "fake_autopilot_cmd",
    "autopilot_cmd",
    "landmarks_cmd",
    "eval_cmd",
)

#: Source kinds plugged into the frame-source factory, and the module (with ``register()``)
#: that provides each: imported only when such a source is opened, so a ``companion run``
#: on a camera never loads the simulator (docs/architecture.md, "Packages and the direction
#: of imports").
PLUGINS: dict[str, str] = {"sim": "companion.simulated", "follow": "companion.simulated"}

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
    for kind, provider in PLUGINS.items():
        plug_in_module(kind, provider)  # type: ignore[arg-type]
    for name in COMMAND_MODULES:
        module = importlib.import_module(f"companion.cli.{name}")
        before = set(sub.choices)
        module.register(sub)
        for added in set(sub.choices) - before:
            _add_common(sub.choices[added], suppress=True)
    return parser


def positive_seconds(text: str) -> float:
    """``--seconds``: a finite number > 0 (argparse type; a bad one is exit status 2)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text}")
    return value


def _raise_interrupted(signum: int, _frame: FrameType | None) -> None:
    raise Interrupted(signum)


@contextmanager
def _sigterm_unwinds() -> Iterator[None]:
    """SIGTERM outside an event loop's own handler unwinds like Ctrl-C (``finally`` blocks
    run: a database transaction is rolled back, a file closed), then exits 143."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous: Callable[[int, FrameType | None], object] | int | None = signal.getsignal(
        signal.SIGTERM)
    signal.signal(signal.SIGTERM, _raise_interrupted)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``companion`` console script; returns the exit status.

    The one place where errors become exit statuses (docs/reliability.md): 0 a clean end,
    1 a runtime failure, 2 bad configuration or input, 128 + N stopped by signal N (130
    Ctrl-C, 143 SIGTERM).  Every error a user can cause is one line on stderr
    (:func:`companion.errors.failure_of`); only a bug keeps its traceback.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:
        parser.print_help()
        return EXIT_CONFIG
    setup_logging(args.log_format or "text", args.log_level or "info")
    clear_stop_signals()
    try:
        with _sigterm_unwinds():
            settings = load_settings(args.config, args.sets, getattr(args, "shipped", ()))
            setup_logging(args.log_format or settings.logging.format,
                          args.log_level or settings.logging.level)
            status = int(args.handler(args, settings))
    except KeyboardInterrupt:
        return interrupted_status(signal.SIGINT)
    except Interrupted as stop:
        return interrupted_status(stop.signum)
    except BrokenPipeError:  # e.g. `companion config | head`: not an error
        sys.stdout = open(os.devnull, "w")
        return EXIT_OK
    except Exception as err:
        failure = failure_of(err)
        if failure is None:
            raise  # a bug: keep its traceback
        print(failure[1], file=sys.stderr)
        return failure[0]
    signum = stop_signal()
    if status == EXIT_OK and signum is not None:
        return interrupted_status(signum)
    return status
