"""The autopilot's side sensors as the pose solver takes them, in one place.

A flight hands the perception a reader ``t_us -> SideSensors`` (the attitude, height and
range at a frame's capture time: :class:`companion.sensors.SensorHistory` in a flight, the
simulator's truth in tests and benchmarks).  :class:`SideInputs` reads it for each frame,
corrects the attitude by the error learnt from earlier fixes (``pose.learn_attitude_bias``,
tracker/pose/attitude_bias.py), learns from each solution, and counts the fixes for which
the solver rejected the autopilot's attitude (each an event).  Worker thread only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from tracker.pose.attitude_bias import AttitudeBias
from tracker.pose.config import PoseConfig
from tracker.pose.types import AltitudeSample, AttitudeSample, NoFix, PoseFix, RangeSample


@dataclass(frozen=True)
class SideSensors:
    """The autopilot's latest attitude, altitude and laser range (any may be missing), and
    its own position estimate: ``position_ned_m`` (LOCAL_POSITION_NED, the map's frame) says
    only where to look for landmarks while no fix comes (:class:`PoseGuess`), never where
    the vehicle is -- it is itself made of our fixes."""

    attitude: AttitudeSample | None = None
    altitude: AltitudeSample | None = None
    laser: RangeSample | None = None
    position_ned_m: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class PoseGuess:
    """Where the autopilot believes the vehicle is, and its attitude: for acquisition to
    predict where landmarks are when the frame has no fix (issue 19: a plate entering the
    image while nothing else is in view).  Same attribute names as a
    :class:`~tracker.pose.types.PoseFix`'s pose."""

    position_ned_m: tuple[float, float, float]
    attitude_rpy_rad: tuple[float, float, float]


def guess_of(read: SideSensors) -> PoseGuess | None:
    """The autopilot's pose from its side sensors; None without position or attitude."""
    att = read.attitude
    if read.position_ned_m is None or att is None:
        return None
    return PoseGuess(read.position_ned_m, (att.roll_rad, att.pitch_rad, att.yaw_rad))


#: Reads the side sensors at a capture time (us).
SensorReader = Callable[[int], SideSensors]


def no_sensors(_t_us: int) -> SideSensors:
    """No side sensor at all (the solver then works from the landmarks alone)."""
    return SideSensors()


class SideInputs:
    """The side sensors of each frame, their attitude corrected; what the fixes said of it."""

    def __init__(self, read: SensorReader, pose_config: PoseConfig) -> None:
        self.read = read
        #: the autopilot's attitude error learnt from the fixes (None: not learnt)
        self.bias = AttitudeBias(pose_config) if pose_config.learn_attitude_bias else None
        #: fixes for which the autopilot's attitude disagreed with the landmarks' (not used)
        self.attitude_rejections = 0

    def at(self, t_us: int) -> tuple[SideSensors, SideSensors]:
        """The side sensors at ``t_us`` as read, and as the solver takes them (the
        attitude corrected by the learnt error)."""
        read = self.read(t_us)
        if self.bias is None:
            return read, read
        return read, replace(read, attitude=self.bias.correct(read.attitude))

    def learn(self, read: SideSensors, fix: PoseFix | NoFix) -> None:
        """Learn the attitude error from a solution (with the attitude as read)."""
        if self.bias is not None:
            self.bias.learn(read.attitude, fix)

    def rejected(self, fix: PoseFix) -> list[dict[str, Any]]:
        """The event of a fix that rejected the autopilot's attitude (counted), else none."""
        if fix.attitude_prior != "rejected":
            return []
        self.attitude_rejections += 1
        why = next(n for n in fix.notes if n.startswith("attitude prior rejected"))
        return [{"event": "attitude prior rejected", "detail": why,
                 "count": self.attitude_rejections}]
