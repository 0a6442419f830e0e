"""Scripted drone trajectories: waypoints flown at given speeds, holds, or a hover."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from mavlink_bridge.fake_vehicle import GuidedVehicle
from tracker.geometry import FloatArray, rotation_from_rpy

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Waypoint:
    """A point to fly to (local NED, m), the speed to get there, the heading on arrival.

    ``speed_m_s``: speed on the leg that ends here; ``yaw_deg``: heading at this waypoint
    (interpolated along the leg the short way round); ``hold_s``: time spent here;
    ``yaw_rate_deg_s``: limits how fast the heading turns (a leg lasts at least
    ``|turn| / yaw_rate_deg_s``, which lets a drone turn on the spot).
    """

    ned_m: Vec3 = (0.0, 0.0, -5.0)
    speed_m_s: float = field(default=2.0, metadata={"gt": 0})
    yaw_deg: float = 0.0
    hold_s: float = field(default=0.0, metadata={"ge": 0})
    yaw_rate_deg_s: float = field(default=30.0, metadata={"gt": 0})


@dataclass(frozen=True)
class TrajectoryConfig:
    """Waypoints in order (the first is the start); ``loop`` flies back to the first.

    ``tilt_deg_per_m_s`` tilts the body into the direction of travel like a multirotor
    (pitch down when flying forward); ``sway_m``/``sway_period_s`` add a slow circular
    drift to the whole path (a hover that is not frozen).

    ``guided``: the waypoints are position targets flown as the fake autopilot flies
    ``--fly``'s setpoints (:class:`FlownPath`): each is the target for its ``hold_s``
    (the first is the start, hovering), approached with limited speed and acceleration,
    the body tilted by the acceleration; ``speed_m_s``, ``tilt_deg_per_m_s``, ``sway_*``
    and ``loop`` do not apply.
    """

    waypoints: tuple[Waypoint, ...] = (Waypoint(),)
    loop: bool = False
    guided: bool = False
    tilt_deg_per_m_s: float = 0.0
    sway_m: float = field(default=0.0, metadata={"ge": 0})
    sway_period_s: float = field(default=10.0, metadata={"gt": 0})


@dataclass(frozen=True)
class KinematicState:
    """The vehicle's motion at one time: NED position/velocity, ZYX attitude and body rates.

    Not ``mavlink_bridge.vehicle.VehicleState``, the truth the fake autopilot reports
    (with the range finder's reading): :meth:`Simulator.autopilot_truth` makes one of this.
    """

    t_s: float
    position_ned_m: Vec3
    velocity_ned_m_s: Vec3
    attitude_rpy_rad: Vec3
    body_rates_rad_s: Vec3 = (0.0, 0.0, 0.0)

    @property
    def r_ned_body(self) -> FloatArray:
        """Rotation taking body vectors to NED."""
        return rotation_from_rpy(*self.attitude_rpy_rad)


@dataclass(frozen=True)
class _Leg:
    t0_s: float
    move_s: float  # flying time; the hold follows
    hold_s: float
    p0: FloatArray
    p1: FloatArray
    yaw0: float
    dyaw: float


def _wrap(a: float) -> float:
    """Angle to (-pi, pi]."""
    return math.atan2(math.sin(a), math.cos(a))


class Trajectory:
    """Piecewise-linear flight through waypoints; :meth:`state_at` is the shared truth."""

    def __init__(self, config: TrajectoryConfig) -> None:
        if not config.waypoints:
            raise ValueError("waypoints: expected at least one waypoint")
        if config.guided and config.loop:
            raise ValueError("trajectory: guided and loop cannot be combined")
        self.config = config
        self.flown = FlownPath(config.waypoints) if config.guided else None
        wps = list(config.waypoints)
        if config.loop and len(wps) > 1:
            wps.append(wps[0])
        self._legs: list[_Leg] = []
        t = 0.0
        first = wps[0]
        self._legs.append(self._leg(t, first, first))
        t += first.hold_s
        for a, b in itertools.pairwise(wps):
            leg = self._leg(t, a, b)
            self._legs.append(leg)
            t += leg.move_s + leg.hold_s
        self.duration_s = t if self.flown is None else self.flown.duration_s

    @staticmethod
    def _leg(t0: float, a: Waypoint, b: Waypoint) -> _Leg:
        p0, p1 = np.asarray(a.ned_m, dtype=np.float64), np.asarray(b.ned_m, dtype=np.float64)
        yaw0 = math.radians(a.yaw_deg)
        dyaw = _wrap(math.radians(b.yaw_deg) - yaw0)
        if a is b:
            return _Leg(t0, 0.0, a.hold_s, p0, p0, yaw0, 0.0)
        move = max(float(np.linalg.norm(p1 - p0)) / b.speed_m_s,
                   abs(math.degrees(dyaw)) / b.yaw_rate_deg_s)
        return _Leg(t0, move, b.hold_s, p0, p1, yaw0, dyaw)

    def _find(self, t_s: float) -> tuple[_Leg, float]:
        t = t_s
        if self.config.loop and self.duration_s > 0:
            t = t_s % self.duration_s
        for leg in reversed(self._legs):
            if t >= leg.t0_s:
                return leg, t - leg.t0_s
        return self._legs[0], 0.0

    def state_at(self, t_s: float) -> KinematicState:
        """The vehicle state at ``t_s`` seconds after the start (clamped at the end)."""
        if self.flown is not None:
            return self.flown.state_at(t_s)
        leg, dt = self._find(t_s)
        if leg.move_s > 0 and dt < leg.move_s:
            s = dt / leg.move_s
            pos = leg.p0 + s * (leg.p1 - leg.p0)  # p(t) = p0 + (t/T)(p1 - p0)
            vel = (leg.p1 - leg.p0) / leg.move_s
            yaw = leg.yaw0 + s * leg.dyaw
            yaw_rate = leg.dyaw / leg.move_s
        else:
            pos, vel = leg.p1.copy(), np.zeros(3)
            yaw, yaw_rate = leg.yaw0 + leg.dyaw, 0.0
        pos, vel = self._sway(t_s, pos, vel)
        roll, pitch = self._tilt(vel, yaw)
        return KinematicState(
            t_s=float(t_s),
            position_ned_m=(float(pos[0]), float(pos[1]), float(pos[2])),
            velocity_ned_m_s=(float(vel[0]), float(vel[1]), float(vel[2])),
            attitude_rpy_rad=(roll, pitch, _wrap(yaw)),
            body_rates_rad_s=(0.0, 0.0, float(yaw_rate)),
        )

    def _sway(self, t_s: float, pos: FloatArray, vel: FloatArray) -> tuple[FloatArray, FloatArray]:
        a = self.config.sway_m
        if a == 0.0:
            return pos, vel
        w = 2.0 * math.pi / self.config.sway_period_s
        # circular drift: d(t) = a (sin wt, 1 - cos wt, 0); d'(t) = a w (cos wt, sin wt, 0)
        d = np.array([a * math.sin(w * t_s), a * (1.0 - math.cos(w * t_s)), 0.0])
        dv = np.array([a * w * math.cos(w * t_s), a * w * math.sin(w * t_s), 0.0])
        return pos + d, vel + dv

    def _tilt(self, vel: FloatArray, yaw: float) -> tuple[float, float]:
        k = math.radians(self.config.tilt_deg_per_m_s)
        if k == 0.0:
            return 0.0, 0.0
        fwd = vel[0] * math.cos(yaw) + vel[1] * math.sin(yaw)
        right = -vel[0] * math.sin(yaw) + vel[1] * math.cos(yaw)
        return float(k * right), float(-k * fwd)  # roll into the sideways motion, nose down


class FlownPath:
    """Waypoints flown by the fake autopilot's guided vehicle
    (:class:`mavlink_bridge.fake_vehicle.GuidedVehicle`, its defaults: 2 m/s, 2 m/s^2,
    ArduPilot's 5 m/s^3, the tilt of its acceleration, up to 11.5 deg), integrated once in
    its own 10 ms steps and interpolated: the offline twin of a ``--fly`` flight against
    the strict fake (``TrajectoryConfig.guided``)."""

    def __init__(self, waypoints: tuple[Waypoint, ...]) -> None:
        first = waypoints[0]
        n, e, d = first.ned_m
        vehicle = GuidedVehicle((n, e, 0.0), math.radians(first.yaw_deg))
        vehicle.hover(-d)
        rows, t = [], 0.0
        for i, wp in enumerate(waypoints):
            if i > 0:
                vehicle.goto(wp.ned_m, math.radians(wp.yaw_deg))
            end = t + wp.hold_s
            while t < end - 1e-9:
                s = vehicle(t)
                rows.append((t, *s.position_ned_m, *s.velocity_ned_m_s, *s.attitude_rpy_rad))
                t = round(t + vehicle.step_s, 9)
                vehicle.step_to(t)
        s = vehicle(t)
        rows.append((t, *s.position_ned_m, *s.velocity_ned_m_s, *s.attitude_rpy_rad))
        self.samples = np.array(rows, dtype=np.float64)
        self.samples[:, 9] = np.unwrap(self.samples[:, 9])
        self.duration_s = t

    def state_at(self, t_s: float) -> KinematicState:
        """The state at ``t_s`` (linear between the vehicle's steps; clamped at the ends)."""
        times = self.samples[:, 0]
        v = np.array([np.interp(t_s, times, col) for col in self.samples[:, 1:].T])
        i = int(np.clip(np.searchsorted(times, t_s), 1, len(times) - 1))
        dt = times[i] - times[i - 1]
        rates = (self.samples[i, 7:10] - self.samples[i - 1, 7:10]) / dt
        return KinematicState(
            t_s=float(t_s),
            position_ned_m=(float(v[0]), float(v[1]), float(v[2])),
            velocity_ned_m_s=(float(v[3]), float(v[4]), float(v[5])),
            attitude_rpy_rad=(float(v[6]), float(v[7]), _wrap(float(v[8]))),
            body_rates_rad_s=(float(rates[0]), float(rates[1]), float(rates[2])),
        )
