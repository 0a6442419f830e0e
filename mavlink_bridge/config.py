"""Configuration of the MAVLink bridge: one frozen dataclass, every field defaulted.

Constraints live in field metadata (``ge``/``gt``/``le``/``lt``/``min_len``) and are checked
by the application's loader; :meth:`MavlinkConfig.check` repeats the cross-field rules that
metadata cannot express.  See docs/mavlink.md for why each default was chosen.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from fieldbounds import check_bounds

Profile = Literal["ardupilot", "px4"]
Backend = Literal["pymavlink", "mavsdk"]
VisionOutput = Literal["vpe", "odometry"]


@dataclass(frozen=True)
class MavlinkConfig:
    """Everything the bridge needs to talk to one autopilot.

    ``endpoint``: ``udpin:HOST:PORT`` (listen), ``udpout:HOST:PORT`` (send to),
    ``tcp:HOST:PORT`` (connect), ``tcpin:HOST:PORT`` (listen), ``serial:DEVICE:BAUD``, or
    any other spelling of mavutil, MAVProxy, MAVSDK or MAVROS in docs/mavlink.md's table
    (:func:`mavlink_bridge.endpoint.parse_endpoint`).
    """

    endpoint: str = field(default="udpout:127.0.0.1:14550", metadata={"min_len": 5})
    profile: Profile = "ardupilot"
    backend: Backend = "pymavlink"
    # 0 = adopt the system id of the first autopilot heard (ArduPilot's sysid enforcement
    # accepts only its own sysid or the GCS's); 1 is used until the autopilot is heard.
    system_id: int = field(default=0, metadata={"ge": 0, "le": 255})
    component_id: int = field(default=197, metadata={"ge": 1, "le": 255})
    output: VisionOutput = "odometry"
    rate_hz: float = field(default=30.0, metadata={"ge": 4.0, "le": 50.0})
    max_fix_age_ms: float = field(default=200.0, metadata={"gt": 0.0, "le": 1000.0})
    landing_target_rate_hz: float = field(default=20.0, metadata={"ge": 1.0, "le": 50.0})
    heartbeat_rate_hz: float = field(default=1.0, metadata={"ge": 0.5, "le": 10.0})
    link_timeout_s: float = field(default=3.0, metadata={"gt": 0.0})
    reconnect_backoff_s: float = field(default=1.0, metadata={"gt": 0.0})
    health_timeout_s: float = field(default=2.0, metadata={"gt": 0.0})
    signing_key_file: str = ""
    signing_link_id: int = field(default=0, metadata={"ge": 0, "le": 255})
    # Message names accepted unsigned while signing is on (ArduPilot lets RADIO_STATUS through).
    allow_unsigned: tuple[str, ...] = ("RADIO_STATUS",)
    set_origin: bool = True
    origin_lat_deg: float = field(default=0.0, metadata={"ge": -90.0, "le": 90.0})
    origin_lon_deg: float = field(default=0.0, metadata={"ge": -180.0, "le": 180.0})
    origin_alt_m: float = 0.0
    origin_retry_s: float = field(default=0.5, metadata={"gt": 0.0})
    statustext_prefix: str = "LMC: "
    statustext_min_interval_s: float = field(default=0.2, metadata={"ge": 0.0})
    rx_queue_len: int = field(default=64, metadata={"ge": 1})
    # Incoming budget: datagrams beyond this many bytes per second are dropped unparsed
    # (counted), so a flooding peer cannot starve the heartbeat.
    rx_budget_bytes_per_s: int = field(default=2_000_000, metadata={"ge": 1000})
    # The messages asked of the autopilot with SET_MESSAGE_INTERVAL on link-up and after a
    # reboot, as (name, rate_hz); the application derives them from its configuration
    # (mavlink_bridge.streams.needed_streams).  Empty: ask for nothing.
    streams: tuple[tuple[str, float], ...] = ()
    stream_check_s: float = field(default=0.25, metadata={"gt": 0.0})

    def check(self) -> None:
        """Raise ``ValueError`` naming the field when a bound in its metadata or a
        cross-field rule is broken (a config built in code skips the TOML loader's checks)."""
        check_bounds(self, "mavlink")
        if self.set_origin and self.origin_lat_deg == 0.0 and self.origin_lon_deg == 0.0:
            raise ValueError(
                "mavlink.origin_lat_deg/origin_lon_deg: expected the EKF origin when "
                "set_origin is true, got 0, 0"
            )
