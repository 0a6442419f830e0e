"""MAVLink I/O for the companion: link, vision output per autopilot, fake autopilot.

Never imports ``tracker`` or ``companion``.  See docs/mavlink.md.
"""

from mavlink_bridge.bridge import PymavlinkBridge, VisionBridge, create_bridge
from mavlink_bridge.config import MavlinkConfig
from mavlink_bridge.errors import MavlinkBridgeError
from mavlink_bridge.messages import LandingTargetFix, VisionFix
from mavlink_bridge.output import SendResult
from mavlink_bridge.telemetry import Telemetry

__all__ = [
    "LandingTargetFix",
    "MavlinkBridgeError",
    "MavlinkConfig",
    "PymavlinkBridge",
    "SendResult",
    "Telemetry",
    "VisionBridge",
    "VisionFix",
    "create_bridge",
]
