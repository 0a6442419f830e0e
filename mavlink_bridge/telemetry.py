"""Typed telemetry from the autopilot, built from a message's field dictionary.

Both backends produce the same types: pymavlink gives ``msg.to_dict()``, mavsdk's
MavlinkDirect plugin gives the fields as JSON.  Field names carry units.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

TELEMETRY_NAMES = (
    "HEARTBEAT", "ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "SYSTEM_TIME",
    "TIMESYNC", "HOME_POSITION", "EKF_STATUS_REPORT", "DISTANCE_SENSOR", "STATUSTEXT",
    "GPS_GLOBAL_ORIGIN", "COMMAND_ACK",
)


@dataclass(frozen=True)
class Attitude:
    time_boot_ms: int
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    rollspeed_rad_s: float
    pitchspeed_rad_s: float
    yawspeed_rad_s: float


@dataclass(frozen=True)
class LocalPositionNed:
    time_boot_ms: int
    north_m: float
    east_m: float
    down_m: float
    north_m_s: float
    east_m_s: float
    down_m_s: float


@dataclass(frozen=True)
class GlobalPosition:
    time_boot_ms: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    relative_alt_m: float

    @property
    def has_origin(self) -> bool:
        """ArduPilot reports 0, 0 until the EKF has an origin."""
        return self.lat_deg != 0.0 or self.lon_deg != 0.0


@dataclass(frozen=True)
class SystemTime:
    time_unix_us: int
    time_boot_ms: int


@dataclass(frozen=True)
class TimeSync:
    tc1_ns: int
    ts1_ns: int


@dataclass(frozen=True)
class GeoPoint:
    """HOME_POSITION or GPS_GLOBAL_ORIGIN."""

    lat_deg: float
    lon_deg: float
    alt_m: float


@dataclass(frozen=True)
class EkfStatus:
    flags: int
    velocity_variance: float
    pos_horiz_variance: float
    pos_vert_variance: float
    compass_variance: float


@dataclass(frozen=True)
class DistanceSensor:
    time_boot_ms: int
    distance_m: float
    min_distance_m: float
    max_distance_m: float
    orientation: int
    sensor_id: int


@dataclass(frozen=True)
class StatusText:
    severity: int
    text: str


@dataclass(frozen=True)
class Heartbeat:
    type: int
    autopilot: int
    base_mode: int
    custom_mode: int
    system_status: int


@dataclass(frozen=True)
class CommandAck:
    command: int
    result: int


@dataclass(frozen=True)
class Telemetry:
    """One received message: who sent it, when (companion monotonic ns), and its value."""

    name: str
    system_id: int
    component_id: int
    received_ns: int
    value: Any


def _f(d: Mapping[str, Any], key: str) -> float:
    return float(d.get(key, 0.0))


def _i(d: Mapping[str, Any], key: str) -> int:
    return int(d.get(key, 0))


def _text(d: Mapping[str, Any]) -> str:
    t = d.get("text", "")
    if isinstance(t, bytes | bytearray):
        t = t.decode("utf-8", errors="replace")
    return str(t).rstrip("\x00")


_CONVERTERS: dict[str, Callable[[Mapping[str, Any]], Any]] = {
    "HEARTBEAT": lambda d: Heartbeat(_i(d, "type"), _i(d, "autopilot"), _i(d, "base_mode"),
                                     _i(d, "custom_mode"), _i(d, "system_status")),
    "ATTITUDE": lambda d: Attitude(_i(d, "time_boot_ms"), _f(d, "roll"), _f(d, "pitch"),
                                   _f(d, "yaw"), _f(d, "rollspeed"), _f(d, "pitchspeed"),
                                   _f(d, "yawspeed")),
    "LOCAL_POSITION_NED": lambda d: LocalPositionNed(_i(d, "time_boot_ms"), _f(d, "x"),
                                                     _f(d, "y"), _f(d, "z"), _f(d, "vx"),
                                                     _f(d, "vy"), _f(d, "vz")),
    "GLOBAL_POSITION_INT": lambda d: GlobalPosition(_i(d, "time_boot_ms"), _i(d, "lat") * 1e-7,
                                                    _i(d, "lon") * 1e-7, _i(d, "alt") * 1e-3,
                                                    _i(d, "relative_alt") * 1e-3),
    "SYSTEM_TIME": lambda d: SystemTime(_i(d, "time_unix_usec"), _i(d, "time_boot_ms")),
    "TIMESYNC": lambda d: TimeSync(_i(d, "tc1"), _i(d, "ts1")),
    "HOME_POSITION": lambda d: GeoPoint(_i(d, "latitude") * 1e-7, _i(d, "longitude") * 1e-7,
                                        _i(d, "altitude") * 1e-3),
    "GPS_GLOBAL_ORIGIN": lambda d: GeoPoint(_i(d, "latitude") * 1e-7,
                                            _i(d, "longitude") * 1e-7, _i(d, "altitude") * 1e-3),
    "EKF_STATUS_REPORT": lambda d: EkfStatus(_i(d, "flags"), _f(d, "velocity_variance"),
                                             _f(d, "pos_horiz_variance"),
                                             _f(d, "pos_vert_variance"),
                                             _f(d, "compass_variance")),
    "DISTANCE_SENSOR": lambda d: DistanceSensor(_i(d, "time_boot_ms"),
                                                _i(d, "current_distance") * 0.01,
                                                _i(d, "min_distance") * 0.01,
                                                _i(d, "max_distance") * 0.01,
                                                _i(d, "orientation"), _i(d, "id")),
    "STATUSTEXT": lambda d: StatusText(_i(d, "severity"), _text(d)),
    "COMMAND_ACK": lambda d: CommandAck(_i(d, "command"), _i(d, "result")),
}


def convert(name: str, fields: Mapping[str, Any]) -> Any:
    """Typed value for a telemetry message, or ``None`` for a name we do not convert."""
    conv = _CONVERTERS.get(name)
    return None if conv is None else conv(fields)
