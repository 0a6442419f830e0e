"""The one exception tree of the application, and the exit statuses it maps to.

Every error a user can cause (bad configuration, bad input files, an unreachable peer)
is a :class:`CompanionError`; the CLI prints its message as one line and exits with
:attr:`CompanionError.exit_status`.  ``tracker`` and ``mavlink_bridge`` do not import this
module: they raise ``ValueError`` (bad arguments) or their own errors, which the
application wraps with ``raise ... from err``.  What escapes a command anyway is mapped in
one place, :func:`failure_of` (the table is in docs/reliability.md): an operating-system
error (permission, full disk, read-only file system) is one line and status 1, never a
traceback; only a bug keeps its traceback.
"""

from __future__ import annotations

import signal
import sqlite3

from mavlink_bridge.errors import (
    BackendError,
    EndpointError,
    LinkOpenError,
    MavlinkBridgeError,
    SigningKeyError,
)

#: Exit statuses (docs/reliability.md): a clean end, a runtime failure, bad configuration
#: or input.  A stop asked by a signal exits ``128 + signal number``: 130 SIGINT, 143 SIGTERM.
EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_CONFIG = 2
#: ``run --fly`` stopped commanding: the vehicle disarmed, changed mode or failed safe
EXIT_FLIGHT_ABORTED = 3


class CompanionError(Exception):
    """Root of all errors the application reports to a user as one line."""

    exit_status = EXIT_FAILURE


class ConfigError(CompanionError):
    """Bad configuration: names the file, the key path and what was expected."""

    exit_status = EXIT_CONFIG


class InputError(CompanionError):
    """Bad input data (a stream folder, a landmark map, a model file...)."""

    exit_status = EXIT_CONFIG


class SourceError(CompanionError):
    """A frame source that cannot be opened or that stopped delivering."""


class LinkError(CompanionError):
    """The autopilot link cannot be opened or was lost for good."""


class Interrupted(BaseException):  # like KeyboardInterrupt: not an Exception
    """SIGTERM outside an event loop's own handler: unwind, then exit 128 + signum."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_stop_signals: list[int] = []


def note_stop_signal(signum: int) -> None:
    """Remember that a signal asked the process to stop (the CLI exits 128 + signum)."""
    _stop_signals.append(int(signum))


def stop_signal() -> int | None:
    """The first signal that asked the process to stop, or None."""
    return _stop_signals[0] if _stop_signals else None


def clear_stop_signals() -> None:
    """Forget earlier stop signals (the CLI calls it as it starts a command)."""
    _stop_signals.clear()


def interrupted_status(signum: int) -> int:
    """The shell's convention for a process stopped by ``signum``: 128 + signum."""
    return 128 + int(signum)


def os_error_line(err: OSError) -> str:
    """An operating-system error as one line: the file(s), then the system's reason."""
    reason = err.strerror or str(err) or type(err).__name__
    names = [str(n) for n in (err.filename, err.filename2) if n is not None]
    return f"{' -> '.join(names)}: {reason}" if names else reason


def failure_of(err: BaseException) -> tuple[int, str] | None:
    """The exit status and the one line for an error a user can cause; None for a bug.

    ``mavlink_bridge`` errors: a connection string or signing key that cannot be used is
    configuration (2); a link that cannot be opened or a backend that fails is a runtime
    failure (1).  ``OSError`` (permission, full disk, read-only file system, missing
    directory) and ``sqlite3.Error`` (a read-only or full landmark database) are runtime
    failures (1) that name the file and the system's reason.
    """
    if isinstance(err, CompanionError):
        return err.exit_status, str(err)
    if isinstance(err, EndpointError | SigningKeyError):
        return EXIT_CONFIG, f"mavlink: {err}"
    if isinstance(err, LinkOpenError | BackendError | MavlinkBridgeError):
        return EXIT_FAILURE, f"mavlink: {err}"
    if isinstance(err, OSError):
        return EXIT_FAILURE, os_error_line(err)
    if isinstance(err, sqlite3.Error):
        return EXIT_FAILURE, f"landmark database: {err}"
    if isinstance(err, UnicodeDecodeError):
        return EXIT_CONFIG, f"cannot decode a file as UTF-8: {err.reason} at byte {err.start}"
    return None
