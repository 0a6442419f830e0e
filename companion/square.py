"""``companion run --fly``: arm a SITL vehicle and fly a small square with position targets.

So the closed loop (docs/sitl.md) is exercised while moving, not only while parked.
ArduPilot: GUIDED (custom mode 4), arm, NAV_TAKEOFF, then SET_POSITION_TARGET_LOCAL_NED
to each corner.  PX4: setpoints streamed first (offboard needs them), OFFBOARD (main
mode 6), arm; the first corner is straight above home at the altitude.  Only for a
simulator: it arms motors.

Once armed the vehicle is watched on every setpoint: a disarm, a mode other than the one it
set (an EKF failsafe switches ArduCopter to LAND, PX4 to AUTO.LAND) or a HEARTBEAT saying
MAV_STATE_CRITICAL / EMERGENCY (a failsafe) stops the commands at once, and
:meth:`SquareFlight.run` raises :class:`FlightAbortedError` naming why (with the autopilot's last
STATUSTEXT), so ``companion run --fly`` stops and exits non-zero.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from companion.errors import EXIT_FLIGHT_ABORTED, CompanionError

log = logging.getLogger(__name__)

MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 0x80
MAV_FRAME_LOCAL_NED = 1
ARDUCOPTER_GUIDED = 4
PX4_MAIN_MODE_OFFBOARD = 6
MAV_STATE_CRITICAL = 5
#: ArduCopter's custom modes (ArduCopter/mode.h) for the messages
ARDUCOPTER_MODES = {0: "STABILIZE", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER",
                    6: "RTL", 9: "LAND", 16: "POSHOLD", 17: "BRAKE", 21: "SMART_RTL"}
#: PX4 main modes (src/modules/commander/px4_custom_mode.h); AUTO (4) sub-modes
PX4_MAIN_MODES = {1: "MANUAL", 2: "ALTCTL", 3: "POSCTL", 4: "AUTO", 5: "ACRO", 6: "OFFBOARD",
                  7: "STABILIZED"}
PX4_AUTO_SUB = {2: "TAKEOFF", 3: "LOITER", 4: "MISSION", 5: "RTL", 6: "LAND"}


class FlightAbortedError(CompanionError):
    """``--fly`` stopped commanding: the vehicle disarmed, changed mode or is in failsafe."""

    exit_status = EXIT_FLIGHT_ABORTED


def mode_name(profile: str, custom_mode: int) -> str:
    """A HEARTBEAT custom_mode as the autopilot's name for it."""
    if profile != "px4":
        return ARDUCOPTER_MODES.get(custom_mode, f"mode {custom_mode}")
    main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
    name = PX4_MAIN_MODES.get(main, f"main mode {main}")
    return f"{name}.{PX4_AUTO_SUB.get(sub, sub)}" if main == 4 else name
#: position and yaw used; velocity, acceleration, force and yaw rate ignored (bits 3-9, 11)
TYPE_MASK_POSITION_YAW = 0b1011_1111_1000


@dataclass(frozen=True)
class SquarePlan:
    """A square of ``side_m`` at ``altitude_m`` starting at ``start_ne_m``, heading fixed.

    The default looks east (yaw 90) along the sample street, whose landmarks stand 8-12 m
    east of home on facades facing west (config/sitl/*.geojson).
    """

    side_m: float = field(default=6.0, metadata={"gt": 0})
    altitude_m: float = field(default=4.0, metadata={"gt": 0})
    yaw_deg: float = 90.0
    leg_s: float = field(default=8.0, metadata={"gt": 0})
    start_ne_m: tuple[float, float] = (0.0, 0.0)
    loops: int = field(default=3, metadata={"ge": 1})
    setpoint_rate_hz: float = field(default=4.0, metadata={"gt": 0})
    climb_m_s: float = field(default=1.0, metadata={"gt": 0})  # ArduCopter's takeoff climb
    settle_s: float = field(default=2.0, metadata={"ge": 0})


def square_corners(plan: SquarePlan) -> list[tuple[float, float, float]]:
    """The corners in local NED (start, then north, east, back south, back west)."""
    n0, e0 = plan.start_ne_m
    s, d = plan.side_m, -plan.altitude_m
    return [(n0, e0, d), (n0 + s, e0, d), (n0 + s, e0 + s, d), (n0, e0 + s, d)]


def position_target_fields(north_m: float, east_m: float, down_m: float, yaw_rad: float,
                           target_system: int, time_boot_ms: int) -> dict[str, Any]:
    """SET_POSITION_TARGET_LOCAL_NED fields for a position + yaw target in LOCAL_NED."""
    return {"time_boot_ms": time_boot_ms & 0xFFFFFFFF, "target_system": target_system,
            "target_component": 1, "coordinate_frame": MAV_FRAME_LOCAL_NED,
            "type_mask": TYPE_MASK_POSITION_YAW, "x": north_m, "y": east_m, "z": down_m,
            "vx": 0.0, "vy": 0.0, "vz": 0.0, "afx": 0.0, "afy": 0.0, "afz": 0.0,
            "yaw": yaw_rad, "yaw_rate": 0.0}


class SquareFlight:
    """Flies :class:`SquarePlan` through ``link`` (``send(name, **fields)``,
    ``autopilot_sysid``) reading the armed state from ``latest("HEARTBEAT")``."""

    def __init__(self, link: Any, latest: Callable[[str], Any], profile: str,
                 plan: SquarePlan | None = None, arm_timeout_s: float = 120.0,
                 arm_retry_s: float = 2.0) -> None:
        self.link = link
        self.latest = latest
        self.profile = profile
        self.plan = plan or SquarePlan()
        self.arm_timeout_s = arm_timeout_s
        self.arm_retry_s = arm_retry_s
        self._t0 = time.monotonic()
        self.flying_mode: int | None = None  # the custom mode the vehicle flies the square in
        self.aborted: str | None = None

    @property
    def target(self) -> int:
        return int(getattr(self.link, "autopilot_sysid", None) or 1)

    def command(self, command: int, *params: float) -> None:
        p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
        self.link.send("COMMAND_LONG", target_system=self.target, target_component=1,
                       command=command, confirmation=0, param1=p[0], param2=p[1],
                       param3=p[2], param4=p[3], param5=p[4], param6=p[5], param7=p[6])

    def setpoint(self, ned: tuple[float, float, float]) -> None:
        boot_ms = int((time.monotonic() - self._t0) * 1000)
        self.link.send("SET_POSITION_TARGET_LOCAL_NED", **position_target_fields(
            *ned, math.radians(self.plan.yaw_deg), self.target, boot_ms))

    def armed(self) -> bool:
        hb = self.latest("HEARTBEAT")
        return hb is not None and bool(hb.value.base_mode & MAV_MODE_FLAG_SAFETY_ARMED)

    async def arm(self) -> None:
        """Mode and arm, retried every ``arm_retry_s`` until armed (the EKF needs the
        fixes first)."""
        first = square_corners(self.plan)[0]
        deadline = time.monotonic() + self.arm_timeout_s
        while not self.armed():
            if time.monotonic() > deadline:
                raise TimeoutError(f"--fly: not armed after {self.arm_timeout_s:g} s "
                                   "(pre-arm checks: see the autopilot's STATUSTEXT)")
            if self.profile == "px4":
                for _ in range(8):  # offboard needs a setpoint stream before the switch
                    self.setpoint(first)
                    await asyncio.sleep(0.1)
                self.command(MAV_CMD_DO_SET_MODE, MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                             PX4_MAIN_MODE_OFFBOARD)
            else:
                self.command(MAV_CMD_DO_SET_MODE, MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                             ARDUCOPTER_GUIDED)
            self.command(MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
            await asyncio.sleep(self.arm_retry_s)
        hb = self.latest("HEARTBEAT")
        self.flying_mode = None if hb is None else int(hb.value.custom_mode)
        log.info("--fly: armed in %s", "?" if self.flying_mode is None
                 else mode_name(self.profile, self.flying_mode))

    def problem(self) -> str | None:
        """Why the square must stop now (disarmed, mode changed, failsafe), else None."""
        hb = self.latest("HEARTBEAT")
        if hb is None:
            return None
        v = hb.value
        if not v.base_mode & MAV_MODE_FLAG_SAFETY_ARMED:
            return "the vehicle disarmed"
        if self.flying_mode is not None and int(v.custom_mode) != self.flying_mode:
            return (f"the autopilot changed mode to {mode_name(self.profile, v.custom_mode)} "
                    f"(was {mode_name(self.profile, self.flying_mode)})")
        if v.system_status >= MAV_STATE_CRITICAL:
            return "the autopilot reports a failsafe (MAV_STATE_CRITICAL)"
        return None

    def _check(self) -> None:
        why = self.problem()
        if why is None:
            return
        text = self.latest("STATUSTEXT")
        said = f"; autopilot: \"{text.value.text}\"" if text is not None else ""
        self.aborted = why
        raise FlightAbortedError(f"--fly stopped commanding: {why}{said}")

    async def run(self) -> None:
        """Arm, take off and fly the square ``loops`` times, then hold the first corner."""
        await self.arm()
        corners = square_corners(self.plan)
        if self.profile != "px4":
            self.command(MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, self.plan.altitude_m)
            climb_end = time.monotonic() + self.plan.altitude_m / self.plan.climb_m_s \
                + self.plan.settle_s
            while time.monotonic() < climb_end:
                self._check()
                await asyncio.sleep(0.1)
        period_s = 1.0 / self.plan.setpoint_rate_hz
        for lap in range(self.plan.loops):
            for corner in [*corners[1:], corners[0]]:
                log.info("--fly: lap %d to N %.1f E %.1f", lap + 1, corner[0], corner[1])
                for _ in range(max(1, round(self.plan.leg_s / period_s))):
                    self._check()
                    self.setpoint(corner)
                    await asyncio.sleep(period_s)
        log.info("--fly: %d laps done; holding the first corner", self.plan.loops)
        while True:  # hold: PX4 leaves offboard without a setpoint stream
            self._check()
            self.setpoint(corners[0])
            await asyncio.sleep(period_s)
