"""The fake autopilot's flight modes, arming and EKF failsafe, and a guided vehicle.

Modes (HEARTBEAT ``custom_mode``): ArduCopter numbers (GUIDED 4, LAND 9; ArduCopter/mode.h);
PX4's ``custom_mode`` is ``main_mode << 16 | sub_mode << 24`` (OFFBOARD main 6, AUTO.LAND main
4 sub 6; src/modules/commander/px4_custom_mode.h).

Rules copied from the autopilots:

* Arming without an external-nav position: refused with "PreArm: VisOdom: not healthy"
  (ArduPilot, ../shared/MAVLINK.md); PX4 refuses offboard arming without a local position
  ("Arming denied: ... position").
* ArduCopter's EKF failsafe: when the EKF's horizontal position is bad for 1 s while armed
  (ArduCopter/ekf_check.cpp: ten checks at 10 Hz) it sends "EKF variance" and "EKF Failsafe:
  changed to LAND Mode" and switches to LAND.  PX4: the local position invalid for
  ``COM_POS_FS_DELAY`` (default 1 s) while in a position mode: "Failsafe activated:
  switching to Land" (AUTO.LAND) -- src/modules/commander/failsafe.
* LAND descends at ``LAND_SPEED`` 50 cm/s (ArduCopter default; PX4 ``MPC_LAND_SPEED`` 0.7)
  and disarms on the ground.

:class:`GuidedVehicle` is a truth function the fake flies from SET_POSITION_TARGET_LOCAL_NED
(GUIDED / OFFBOARD), NAV_TAKEOFF and LAND: a critically damped approach to the target with
limited speed and acceleration, its tilt following the acceleration.  Its horizontal
acceleration changes no faster than ArduPilot's position controller lets it:
``PSC_JERK_NE`` (``PSC_JERK_XY`` before 4.7), default 5 m/s^3
(libraries/AC_AttitudeControl/AC_PosControl.h, ``POSCONTROL_JERK_NE_MSSS``; PX4's
``MPC_JERK_AUTO``, 4 m/s^3 in the PX4 SITL configurations seen, not read in PX4's own
source here, is of the same size).  Without it the vehicle leaned 11.5
deg within one 10 ms step when a leg began, a turn no copter makes, and a camera frame
matched to an attitude sample one frame old was 11.5 deg off (issue 19).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from mavlink_bridge.vehicle import VehicleState

ARDUCOPTER_GUIDED, ARDUCOPTER_LAND, ARDUCOPTER_STABILIZE = 4, 9, 0
PX4_MAIN_OFFBOARD, PX4_MAIN_AUTO, PX4_SUB_LAND = 6, 4, 6
PX4_OFFBOARD = PX4_MAIN_OFFBOARD << 16
PX4_LAND = (PX4_MAIN_AUTO << 16) | (PX4_SUB_LAND << 24)
MAV_MODE_FLAG_SAFETY_ARMED, MAV_MODE_FLAG_CUSTOM = 0x80, 0x01
MAV_RESULT_ACCEPTED, MAV_RESULT_FAILED = 0, 4
FAILSAFE_CONFIRM_S = 1.0
G = 9.80665


@dataclass
class FlightState:
    """Armed, mode and failsafe of one fake autopilot."""

    profile: str
    armed: bool = False
    custom_mode: int = 0
    failsafe: str | None = None
    events: list[tuple[float, str]] = field(default_factory=list)
    _bad_since_s: float | None = None

    @property
    def landing(self) -> bool:
        return self.custom_mode == (ARDUCOPTER_LAND if self.profile == "ardupilot" else PX4_LAND)

    def heartbeat(self) -> tuple[int, int, int]:
        """(base_mode, custom_mode, system_status): CRITICAL (5) in failsafe, else ACTIVE
        (4) when armed, STANDBY (3) when not (ArduCopter/GCS_Mavlink.cpp)."""
        base = MAV_MODE_FLAG_CUSTOM | (MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        status = 5 if self.failsafe else (4 if self.armed else 3)
        return base, self.custom_mode, status

    def set_mode(self, t_s: float, param2: float, param3: float) -> int:
        """DO_SET_MODE (param1 MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, param2 custom mode; PX4:
        param2 main mode, param3 sub mode)."""
        mode = int(param2) if self.profile == "ardupilot" \
            else (int(param2) << 16) | (int(param3) << 24)
        if self.failsafe is not None and not self._is_land(mode):
            return MAV_RESULT_FAILED  # a position mode needs a position
        self.custom_mode = mode
        self.events.append((t_s, f"mode {mode}"))
        return MAV_RESULT_ACCEPTED

    def _is_land(self, mode: int) -> bool:
        return mode == (ARDUCOPTER_LAND if self.profile == "ardupilot" else PX4_LAND)

    def arm(self, t_s: float, arm: bool, position_ok: bool,
            text: Callable[[str], None]) -> int:
        if not arm:
            self.armed = False
            self.events.append((t_s, "disarmed"))
            return MAV_RESULT_ACCEPTED
        if not position_ok:
            text("PreArm: VisOdom: not healthy" if self.profile == "ardupilot"
                 else "Arming denied: local position required")
            return MAV_RESULT_FAILED
        self.armed = True
        self.events.append((t_s, "armed"))
        return MAV_RESULT_ACCEPTED

    def check_ekf(self, t_s: float, horizontal_ok: bool, text: Callable[[str], None]) -> None:
        """The EKF failsafe (module doc): armed, position bad for 1 s -> LAND."""
        if horizontal_ok or not self.armed:
            self._bad_since_s = None
            return
        if self._bad_since_s is None:
            self._bad_since_s = t_s
            if self.profile == "ardupilot":
                text("VisOdom: not healthy")
        if self.failsafe is None and t_s - self._bad_since_s >= FAILSAFE_CONFIRM_S:
            self.failsafe = "ekf"
            self.custom_mode = ARDUCOPTER_LAND if self.profile == "ardupilot" else PX4_LAND
            self.events.append((t_s, "failsafe LAND"))
            if self.profile == "ardupilot":
                text("EKF variance")
                text("EKF Failsafe: changed to LAND Mode")
            else:
                text("Failsafe activated: switching to Land")


@dataclass
class GuidedVehicle:
    """A copter flown by the fake's commands (module doc); call it as a truth function."""

    start_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw_rad: float = 0.0
    max_speed_m_s: float = 2.0
    max_accel_m_s2: float = 2.0
    max_jerk_m_s3: float = 5.0  # horizontal (module doc: PSC_JERK_NE)
    bandwidth_rad_s: float = 1.2
    land_speed_m_s: float = 0.5
    step_s: float = 0.01
    t_s: float = 0.0
    target: np.ndarray | None = None
    landing: bool = False

    def __post_init__(self) -> None:
        self.p = np.array(self.start_ned_m, float)
        self.v = np.zeros(3)
        self.a = np.zeros(3)
        self._a_ne = np.zeros(2)  # the horizontal acceleration commanded last step
        self.target_yaw = self.yaw_rad

    def on_ground(self) -> bool:
        return self.p[2] >= self.start_ned_m[2] - 0.05

    def hover(self, height_m: float) -> None:
        """Start in the air, ``height_m`` above the start, holding there."""
        self.p[2] = self.start_ned_m[2] - height_m
        self.target = self.p.copy()

    def takeoff(self, altitude_m: float) -> None:
        self.target = np.array([self.p[0], self.p[1], self.start_ned_m[2] - altitude_m])

    def goto(self, ned: tuple[float, float, float], yaw_rad: float) -> None:
        self.target = np.array(ned, float)
        self.target_yaw = yaw_rad

    def step_to(self, t_s: float) -> None:
        """Integrate the motion up to ``t_s``."""
        while self.t_s + self.step_s <= t_s:
            self._step(self.step_s)
            self.t_s += self.step_s

    def _step(self, dt: float) -> None:
        if self.landing:
            want_v = np.array([0.0, 0.0, self.land_speed_m_s if not self.on_ground() else 0.0])
            a = (want_v - self.v) * 2.0
        elif self.target is None:
            a = -self.v * 2.0
        else:  # the PD law w^2 (target - p) - 2 w v, its velocity demand held to the speed
            w = self.bandwidth_rad_s
            want_v = 0.5 * w * (self.target - self.p)
            fast = float(np.linalg.norm(want_v))
            if fast > self.max_speed_m_s:
                want_v *= self.max_speed_m_s / fast
            a = 2.0 * w * (want_v - self.v)
        norm = float(np.linalg.norm(a))
        if norm > self.max_accel_m_s2:
            a *= self.max_accel_m_s2 / norm
        step = a[:2] - self._a_ne
        most, change = self.max_jerk_m_s3 * dt, float(np.linalg.norm(step))
        if change > most:
            a[:2] = self._a_ne + step * (most / change)
        self._a_ne = a[:2].copy()
        v0 = self.v
        self.v = self.v + a * dt
        speed = float(np.linalg.norm(self.v))
        if speed > self.max_speed_m_s:
            self.v *= self.max_speed_m_s / speed
        self.p = self.p + self.v * dt
        if self.p[2] > self.start_ned_m[2]:  # the ground
            self.p[2], self.v[2] = self.start_ned_m[2], min(self.v[2], 0.0)
        self.a = (self.v - v0) / dt  # what the accelerometer feels
        dyaw = math.remainder(self.target_yaw - self.yaw_rad, math.tau)
        self.yaw_rad += max(-1.0 * dt, min(1.0 * dt, dyaw))

    def acceleration(self) -> np.ndarray:
        return self.a.copy()

    def __call__(self, t_s: float) -> VehicleState:
        """The state now (``t_s`` only labels it: the vehicle is integrated by the fake)."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        fwd = c * self.a[0] + s * self.a[1]
        right = -s * self.a[0] + c * self.a[1]
        pitch, roll = -math.atan2(fwd, G), math.atan2(right, G)
        height = max(self.start_ned_m[2] - self.p[2], 0.0)
        n, e, d = (float(v) for v in self.p)
        vn, ve, vd = (float(v) for v in self.v)
        return VehicleState(t_s, (n, e, d), (vn, ve, vd), (roll, pitch, self.yaw_rad),
                            height / max(math.cos(roll) * math.cos(pitch), 0.5))
