"""Typed telemetry from the autopilot, built from a message's field dictionary.

Both backends produce the same types: pymavlink gives ``msg.to_dict()``, mavsdk's
MavlinkDirect plugin gives the fields as JSON.  Field names carry units.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncGenerator, Callable, Mapping
from dataclasses import dataclass
from typing import Any

from mavlink_bridge.messages import euler_to_quaternion

TELEMETRY_NAMES = (
    "HEARTBEAT", "ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "SYSTEM_TIME",
    "TIMESYNC", "HOME_POSITION", "EKF_STATUS_REPORT", "DISTANCE_SENSOR", "STATUSTEXT",
    "GPS_GLOBAL_ORIGIN", "COMMAND_ACK", "SIMSTATE", "SIM_STATE", "HIL_STATE_QUATERNION",
    "ODOMETRY",
)
#: Messages that carry a simulator's true pose (never a real vehicle's estimate).
TRUTH_NAMES = ("SIM_STATE", "SIMSTATE", "HIL_STATE_QUATERNION")
#: The one ZYX Euler -> (w, x, y, z) formula is :func:`mavlink_bridge.messages.euler_to_quaternion`;
#: this name stays for the fake autopilot (fake_autopilot.py), which imports it from here.
quaternion_from_rpy = euler_to_quaternion


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
class Odometry:
    """The autopilot's own attitude variance (rad^2; NaN: not reported), from ODOMETRY's
    ``pose_covariance`` (the upper triangle of x, y, z, roll, pitch, yaw: roll at 15, pitch
    at 18, yaw at 20).  PX4 streams its EKF's ``orientation_variance`` there
    (src/modules/mavlink/streams/ODOMETRY.hpp); ArduPilot sends no ODOMETRY."""

    time_usec: int
    attitude_variance_rad2: tuple[float, float, float]

    @property
    def time_boot_ms(self) -> int:
        return self.time_usec // 1000


def _odometry(d: Mapping[str, Any]) -> Odometry:
    cov = list(d.get("pose_covariance") or [])
    var = tuple(float(cov[i]) if len(cov) == 21 else math.nan for i in (15, 18, 20))
    return Odometry(_i(d, "time_usec"), (var[0], var[1], var[2]))


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
class SimTruth:
    """A simulator's true vehicle state (SIM_STATE, SIMSTATE or HIL_STATE_QUATERNION).

    ``quaternion_wxyz``: body FRD -> NED rotation (None for SIMSTATE, which has Euler angles
    only); ``alt_m``: metres above mean sea level, None for SIMSTATE (it has no altitude);
    ``velocity_ned_m_s``: None where the message has none; ``time_usec``: the simulator's
    stamp (HIL_STATE_QUATERNION only, else 0).
    """

    lat_deg: float
    lon_deg: float
    alt_m: float | None
    attitude_rpy_rad: tuple[float, float, float]
    quaternion_wxyz: tuple[float, float, float, float] | None
    velocity_ned_m_s: tuple[float, float, float] | None
    time_usec: int = 0


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


def _simstate(d: Mapping[str, Any]) -> SimTruth:
    """ArduPilot SIMSTATE: Euler angles (rad), lat/lng in degE7, no altitude."""
    return SimTruth(_i(d, "lat") * 1e-7, _i(d, "lng") * 1e-7, None,
                    (_f(d, "roll"), _f(d, "pitch"), _f(d, "yaw")), None, None)


def _sim_state(d: Mapping[str, Any]) -> SimTruth:
    """SIM_STATE: prefer the degE7 extension fields ``lat_int``/``lon_int``.

    Without them (MAVLink 1, ArduPilot before 4.5) the float ``lat``/``lon`` are used;
    ArduPilot wrote degE7 into those floats (|lat| > 90 gives it away), a float32 keeps
    only ~0.4 m of either.
    """
    lat_i, lon_i = _i(d, "lat_int"), _i(d, "lon_int")
    if lat_i != 0 or lon_i != 0:
        lat, lon = lat_i * 1e-7, lon_i * 1e-7
    else:
        lat, lon = _f(d, "lat"), _f(d, "lon")
        if abs(lat) > 90.0 or abs(lon) > 180.0:
            lat, lon = lat * 1e-7, lon * 1e-7
    q = (_f(d, "q1"), _f(d, "q2"), _f(d, "q3"), _f(d, "q4"))
    return SimTruth(lat, lon, _f(d, "alt"), (_f(d, "roll"), _f(d, "pitch"), _f(d, "yaw")),
                    q if any(q) else None, (_f(d, "vn"), _f(d, "ve"), _f(d, "vd")))


def _hil_state_quaternion(d: Mapping[str, Any]) -> SimTruth:
    """PX4 HIL_STATE_QUATERNION: lat/lon degE7, alt mm, quaternion (w, x, y, z), v cm/s."""
    q = tuple(float(v) for v in d.get("attitude_quaternion", (1.0, 0.0, 0.0, 0.0)))
    w, x, y, z = q
    # ZYX Euler from the quaternion (only for display; the quaternion is what is used)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return SimTruth(_i(d, "lat") * 1e-7, _i(d, "lon") * 1e-7, _i(d, "alt") * 1e-3,
                    (roll, pitch, yaw), (w, x, y, z),
                    (_i(d, "vx") * 0.01, _i(d, "vy") * 0.01, _i(d, "vz") * 0.01),
                    _i(d, "time_usec"))


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
    "SIMSTATE": _simstate,
    "SIM_STATE": _sim_state,
    "HIL_STATE_QUATERNION": _hil_state_quaternion,
    "ODOMETRY": _odometry,
}


def convert(name: str, fields: Mapping[str, Any]) -> Any:
    """Typed value for a telemetry message, or ``None`` for a name we do not convert."""
    conv = _CONVERTERS.get(name)
    return None if conv is None else conv(fields)


class TelemetryHub:
    """Latest value per message name, and bounded async streams of new ones.

    Both backends keep their telemetry here.  A slow reader's queue drops its oldest item
    (counted in ``counters["queue_drops"]``), never blocking the receive path.
    """

    def __init__(self, queue_len: int, counters: dict[str, int]) -> None:
        self.queue_len = queue_len
        self.counters = counters
        self.counters.setdefault("queue_drops", 0)
        self._cache: dict[str, Telemetry] = {}
        self._subs: dict[str, set[asyncio.Queue[Telemetry]]] = {}

    def publish(self, item: Telemetry) -> None:
        """Store ``item`` as the latest of its name and hand it to every subscriber."""
        self._cache[item.name] = item
        for q in self._subs.get(item.name, ()):
            if q.full():
                q.get_nowait()
                self.counters["queue_drops"] += 1
            q.put_nowait(item)

    def latest(self, name: str) -> Telemetry | None:
        """The newest item of ``name`` (None before the first)."""
        return self._cache.get(name)

    def subscriber_count(self, name: str) -> int:
        """How many live subscriptions follow ``name`` (a closed stream leaves none)."""
        return len(self._subs.get(name, ()))

    async def subscribe(self, *names: str) -> AsyncGenerator[Telemetry, None]:
        """New items of ``names`` as they arrive; the queue is released in ``finally``."""
        q: asyncio.Queue[Telemetry] = asyncio.Queue(maxsize=self.queue_len)
        for n in names:
            self._subs.setdefault(n, set()).add(q)
        try:
            while True:
                yield await q.get()
        finally:
            for n in names:
                self._subs[n].discard(q)
