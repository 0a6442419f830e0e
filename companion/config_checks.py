"""Checks of what the configuration names, before anything is opened (``companion check``
is the preflight that opens them: companion/preflight.py).

``companion run`` and ``companion config`` call :func:`preflight`; ``companion demo`` calls
:func:`check_flightlog_dir` (its link is its own).  Each failure is a one-line
:class:`~companion.errors.ConfigError` (exit status 2) naming the setting, the value and
why: the connection string (every spelling of docs/mavlink.md), the serial device, the
signing key file, the flight log directory, a camera rate the camera cannot be asked for.
Nothing is created or opened for writing: a directory that does not exist yet is judged by
its nearest existing parent.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from companion.errors import ConfigError
from companion.settings import Settings
from companion.sources.config import camera_rate_refusal
from companion.sources.factory import resolve
from mavlink_bridge.codec import load_signing_key
from mavlink_bridge.endpoint import Endpoint, parse_endpoint
from mavlink_bridge.errors import EndpointError, SigningKeyError


def preflight(settings: Settings) -> None:
    """Everything ``companion run`` needs from the files and devices it names."""
    check_flightlog_dir(settings)
    check_camera_rate(settings)
    endpoint = check_endpoint(settings.mavlink.endpoint)
    if endpoint.kind == "serial":
        check_serial_device(endpoint)
    key = settings.mavlink.signing_key_file
    if key:
        try:
            load_signing_key(key)
        except SigningKeyError as err:
            raise ConfigError(f"mavlink.signing_key_file: {err}") from None


def check_camera_rate(settings: Settings) -> None:
    """``source.camera_fps`` can be asked of the configured camera (other sources do not
    use it: a replay of a recording with the vehicle's file keeps working)."""
    fps, source = settings.source.camera_fps, resolve(settings.source)
    refusal = camera_rate_refusal(source.spec, fps) if fps and source.kind == "camera" \
        else None
    if refusal is not None:
        raise ConfigError(f"source.camera_fps = {fps:g} "
                          f"({settings.origin_of('source.camera_fps')}): {refusal}")


def check_endpoint(spec: str) -> Endpoint:
    """The parsed ``mavlink.endpoint``, or a ConfigError naming the setting."""
    try:
        return parse_endpoint(spec)
    except EndpointError as err:
        raise ConfigError(f"mavlink.endpoint: {err}") from None


def check_serial_device(endpoint: Endpoint) -> None:
    """The serial device exists and is a character device (a tty or a pty)."""
    try:
        mode = os.stat(endpoint.device).st_mode
    except OSError as err:
        raise ConfigError(f"mavlink.endpoint: serial device {endpoint.device}: "
                          f"{err.strerror} (is the autopilot plugged in?)") from None
    if not stat.S_ISCHR(mode):
        raise ConfigError(f"mavlink.endpoint: {endpoint.device} is not a serial device")


def check_flightlog_dir(settings: Settings) -> None:
    """``flightlog.dir`` is a directory this process can write, or can create."""
    check_writable_dir("flightlog.dir", Path(settings.flightlog.dir))


def check_writable_dir(key: str, path: Path) -> None:
    """``path`` is (or can become) a writable directory; else a ConfigError naming ``key``."""
    existing = path.absolute()
    while not existing.exists():
        if existing.is_symlink():  # a dangling link: creating through it fails
            raise ConfigError(f"{key}: {path}: {existing} is a broken symbolic link")
        existing = existing.parent
    if not existing.is_dir():
        raise ConfigError(f"{key}: {path}: {existing} is not a directory")
    if os.statvfs(existing).f_flag & os.ST_RDONLY:
        raise ConfigError(f"{key}: {path}: {existing} is on a read-only file system")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ConfigError(f"{key}: {path}: {existing} is not writable by this user")
