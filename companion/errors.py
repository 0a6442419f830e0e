"""The one exception tree of the application.

Every error a user can cause (bad configuration, bad input files, an unreachable peer)
is a :class:`CompanionError`; the CLI prints its message as one line and exits with
:attr:`CompanionError.exit_status`.  ``tracker`` and ``mavlink_bridge`` do not import this
module: they raise ``ValueError`` (bad arguments) or their own errors, which the
application wraps with ``raise ... from err``.
"""

from __future__ import annotations


class CompanionError(Exception):
    """Root of all errors the application reports to a user as one line."""

    exit_status = 1


class ConfigError(CompanionError):
    """Bad configuration: names the file, the key path and what was expected."""

    exit_status = 2


class InputError(CompanionError):
    """Bad input data (a stream folder, a landmark map, a model file...)."""

    exit_status = 2


class SourceError(CompanionError):
    """A frame source that cannot be opened or that stopped delivering."""


class LinkError(CompanionError):
    """The autopilot link cannot be opened or was lost for good."""
