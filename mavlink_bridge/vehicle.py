"""The scripted vehicle the fake autopilot flies: its true state over time.

Whoever runs the fake autopilot (a test, the simulated world, the CLI) hands it a callable
``truth(time_s) -> VehicleState``; :func:`hover_then_circle` is the default so the fake works
standalone.  Frames: NED metres in the local frame of the EKF origin, body FRD, ZYX Euler.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class VehicleState:
    """True state at ``time_s`` (seconds since the fake autopilot started).

    ``range_m`` is what a downward laser range finder reads (DISTANCE_SENSOR).
    """

    time_s: float
    position_ned_m: Vec3
    velocity_ned_m_s: Vec3
    attitude_rpy_rad: Vec3
    range_m: float


TruthFn = Callable[[float], VehicleState]


def hover_then_circle(
    hover_s: float = 2.0, altitude_m: float = 5.0, radius_m: float = 5.0, period_s: float = 20.0
) -> TruthFn:
    """Hover at the origin for ``hover_s``, then fly a horizontal circle facing along track.

    The circle is centred ``radius_m`` north of the origin and starts at the origin, so the
    position is continuous: p(t) = c + r (-cos w t, sin w t), w = 2 pi / period.
    """
    if period_s <= 0 or radius_m < 0 or altitude_m <= 0:
        raise ValueError("hover_then_circle: expected period_s > 0, radius_m >= 0, altitude_m > 0")
    omega = 2.0 * math.pi / period_s

    def truth(time_s: float) -> VehicleState:
        down = -altitude_m
        if time_s < hover_s or radius_m == 0.0:
            return VehicleState(time_s, (0.0, 0.0, down), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                altitude_m)
        a = omega * (time_s - hover_s)
        north = radius_m - radius_m * math.cos(a)
        east = radius_m * math.sin(a)
        vn, ve = radius_m * omega * math.sin(a), radius_m * omega * math.cos(a)
        yaw = math.atan2(ve, vn)
        # coordinated turn: bank = atan(v^2 / (r g))
        roll = math.atan((radius_m * omega) ** 2 / (radius_m * 9.80665))
        rng = altitude_m / (math.cos(roll))
        return VehicleState(time_s, (north, east, down), (vn, ve, 0.0), (roll, 0.0, yaw), rng)

    return truth
