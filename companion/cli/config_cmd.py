"""``companion config``: print the effective configuration, after every layer."""

from __future__ import annotations

import argparse
import json
import sys

from companion.preflight import preflight
from companion.settings import Settings
from companion.validate import to_plain


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion config``."""
    parser = sub.add_parser(
        "config",
        help="check the configuration and print the effective settings",
        description="Load every configuration layer, validate it and print the result "
        "(as TOML-like text, or JSON with --json).  Exit status 2 on a bad configuration.",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.set_defaults(handler=run)


def _toml_value(value: object) -> str:
    return json.dumps(value) if not isinstance(value, bool) else str(value).lower()


def _print_table(name: str, values: dict[str, object]) -> None:
    print(f"\n[{name}]")
    tables = {k: v for k, v in values.items() if isinstance(v, dict)}
    for key, value in values.items():
        if key not in tables:
            print(f"{key} = {_toml_value(value)}")
    for key, value in tables.items():
        _print_table(f"{name}.{key}", value)


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Print the settings; the loader has validated their values, :func:`preflight` what
    they name (connection string, serial device, signing key, flight log directory)."""
    preflight(settings)
    plain = to_plain(settings)
    files = plain.pop("config_files")
    if args.json:
        print(json.dumps({"files": files, "settings": plain}, indent=2))
        return 0
    print("# files read, in order: " + ", ".join(files))
    for section, values in plain.items():
        _print_table(section, values)
    sys.stdout.flush()
    return 0
