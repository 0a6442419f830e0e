"""Where the shipped configuration is, in a checkout and in an installed wheel alike.

``config/`` of the repository is installed as the package ``companion_config``
(pyproject.toml maps it; docs/decisions.md, "config/ as package data") and found through
:mod:`importlib.resources`, never through a path into the source tree.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path

from companion.errors import ConfigError

CONFIG_PACKAGE = "companion_config"


def config_dir() -> Path:
    """The folder of the shipped configuration (``default.toml``, ``sim.toml``, ...)."""
    try:
        root = importlib.resources.files(CONFIG_PACKAGE)
    except ModuleNotFoundError:
        raise ConfigError(f"the shipped configuration ({CONFIG_PACKAGE}) is not installed; "
                          "reinstall landmark-companion") from None
    if not isinstance(root, Path):  # e.g. run from a zip file: the loader needs real files
        raise ConfigError(f"the shipped configuration is not a folder ({root}); "
                          "install landmark-companion from its wheel, unzipped")
    return root


def scenario_dir() -> Path:
    """The built-in scenarios (``config/scenarios/NAME.toml``)."""
    return config_dir() / "scenarios"


def scenario_path(name_or_file: str) -> Path:
    """A scenario name (``config/scenarios/NAME.toml``) or a file path."""
    path = Path(name_or_file)
    if path.suffix == ".toml" or path.exists():
        return path
    return scenario_dir() / f"{name_or_file}.toml"
