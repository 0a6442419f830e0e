"""``companion config``: print the effective configuration, after every layer."""

from __future__ import annotations

import argparse
import json
import sys

from companion.config_checks import preflight
from companion.core.validate import to_plain
from companion.settings import BUILT_IN, SIM_LAYERS, Settings


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion config``."""
    parser = sub.add_parser(
        "config",
        help="check the configuration and print the effective settings",
        description="Load every configuration layer, validate it and print the result "
        "(as TOML-like text, or JSON with --json), with the layer that set each key.  Exit "
        "status 2 on a bad configuration.",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--sim", action="store_const", const=SIM_LAYERS, default=(),
                        dest="shipped", help="with the simulator's layer (config/sim.toml), "
                        "as companion demo and synth load it")
    parser.set_defaults(handler=run)


def _toml_value(value: object) -> str:
    return json.dumps(value) if not isinstance(value, bool) else str(value).lower()


def _print_table(name: str, values: dict[str, object], origins: dict[str, str]) -> None:
    print(f"\n[{name}]")
    tables = {k: v for k, v in values.items() if isinstance(v, dict)}
    for key, value in values.items():
        if key not in tables:
            print(f"{key} = {_toml_value(value)}  # {origins[f'{name}.{key}']}")
    for key, value in tables.items():
        _print_table(f"{name}.{key}", value, origins)


def leaf_origins(plain: dict[str, object], settings: Settings, prefix: str = ""
                 ) -> dict[str, str]:
    """Every leaf key of the settings -> the layer that set it (or the built-in default)."""
    out: dict[str, str] = {}
    for key, value in plain.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(leaf_origins(value, settings, f"{path}."))
        else:
            out[path] = settings.origin_of(path)
    return out


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Print the settings; the loader has validated their values, :func:`preflight` what
    they name (connection string, serial device, signing key, flight log directory)."""
    preflight(settings)
    plain = to_plain(settings)
    files = plain.pop("config_files")
    for internal in ("origins", "default_file"):
        plain.pop(internal)
    origins = leaf_origins(plain, settings)
    if args.json:
        print(json.dumps({"files": files, "settings": plain, "origins": origins,
                          "noise": "measured" if settings.noise_measured else "uncalibrated"},
                         indent=2))
        return 0
    print("# files read, in order: " + ", ".join(files))
    print(f"# each key's comment: the layer that set it ({BUILT_IN}: no layer did)")
    for section, values in plain.items():
        _print_table(section, values, origins)
    sys.stdout.flush()
    return 0
