"""Optional features and the extra that installs each (pyproject.toml, docs/deploy.md).

A companion computer needs none of them: the PostGIS client (``postgis``), the
dashboard's web server (``dashboard``) and the MAVSDK backend (``mavsdk``).  A feature
that needs a missing one says so in one line, with the command that installs it.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from companion.errors import ConfigError


def install_hint(extra: str) -> str:
    """The command that installs an extra."""
    return f"pip install 'landmark-companion[{extra}]'"


def require(module: str, extra: str, feature: str) -> ModuleType:
    """Import ``module`` or raise a one-line :class:`ConfigError` naming the extra."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise ConfigError(f"{feature} needs the optional package {module.split('.')[0]}, "
                          f"which is not installed: {install_hint(extra)}") from None
