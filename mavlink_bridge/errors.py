"""Exceptions of the MAVLink bridge.

``mavlink_bridge`` does not import the application; the application wraps these errors
(``raise LinkError(...) from err``).  Every message is one line a user can act on.
"""

from __future__ import annotations


class MavlinkBridgeError(Exception):
    """Root of every error raised by :mod:`mavlink_bridge`."""


class EndpointError(MavlinkBridgeError, ValueError):
    """A connection string that cannot be understood (``udpin:HOST:PORT`` ...)."""


class LinkOpenError(MavlinkBridgeError):
    """The endpoint could not be opened (port in use, device missing, peer refused)."""


class SigningKeyError(MavlinkBridgeError):
    """The signing key file is missing, unreadable or not a valid key."""


class BackendError(MavlinkBridgeError):
    """The selected backend failed (for example mavsdk refused a connection URL)."""
