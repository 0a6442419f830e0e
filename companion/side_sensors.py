"""The autopilot's side sensors as the pose solver takes them, in one place.

A flight hands the perception a reader ``t_us -> SideSensors`` (the attitude, height and
range at a frame's capture time: :class:`companion.sensors.SensorHistory` in a flight, the
simulator's truth in tests and benchmarks).  :class:`SideInputs` reads it for each frame,
corrects the attitude by the error learnt from earlier fixes (``pose.learn_attitude_bias``,
tracker/pose/attitude_bias.py), learns from each solution, and counts the fixes for which
the solver rejected the autopilot's attitude (each an event).  Such a fix is held back
(no fix that frame, nothing learnt from it) until the disagreement has repeated on
``pose.attitude_reject_frames`` solved frames in a row: one frame's disagreement is mostly
the landmarks' own (docs/decisions.md, "A disagreement with the autopilot's attitude must
repeat").  Worker thread only.
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
        self._confirm = pose_config.attitude_reject_frames
        self._streak = 0  # solved frames in a row whose landmarks disagreed with it
        self._last_rejected_us: int | None = None

    def at(self, t_us: int) -> tuple[SideSensors, SideSensors]:
        """The side sensors at ``t_us`` as read, and as the solver takes them (the
        attitude corrected by the learnt error)."""
        read = self.read(t_us)
        if self.bias is None:
            return read, read
        return read, replace(read, attitude=self.bias.correct(read.attitude))

    def for_lone_plate(self, read: SideSensors, side: SideSensors) -> SideSensors:
        """``side`` as a lone plate's fix takes it: the attitude corrected with the learnt
        error's floors for one plate (``pose.attitude_bias_lone_floor_*``)."""
        if self.bias is None:
            return side
        return replace(read, attitude=self.bias.correct(read.attitude, lone=True))

    def settle(self, read: SideSensors, fix: PoseFix | NoFix
               ) -> tuple[PoseFix | NoFix, list[dict[str, Any]]]:
        """The solution as the frame gives it, and its event: a fix that rejected the
        autopilot's attitude is counted (an event) and held back -- a :class:`NoFix` --
        until that has happened on ``attitude_reject_frames`` solved frames in a row (each
        within :data:`REJECT_WINDOW_US` of the last); the attitude error is then learnt from
        what is given (with the attitude as read)."""
        events: list[dict[str, Any]] = []
        if isinstance(fix, PoseFix):
            if fix.attitude_prior == "rejected":
                events, fix = self._rejected(fix), self._held(fix)
            else:
                self._streak = 0
        if self.bias is not None:
            self.bias.learn(read.attitude, fix)
        return fix, events

    def _rejected(self, fix: PoseFix) -> list[dict[str, Any]]:
        self.attitude_rejections += 1
        last, self._last_rejected_us = self._last_rejected_us, fix.time_us
        recent = last is not None and 0 <= fix.time_us - last <= REJECT_WINDOW_US
        self._streak = self._streak + 1 if recent else 1
        why = next(n for n in fix.notes if n.startswith("attitude prior rejected"))
        return [{"event": "attitude prior rejected", "detail": why,
                 "count": self.attitude_rejections}]

    def _held(self, fix: PoseFix) -> PoseFix | NoFix:
        if self._streak >= self._confirm:
            return fix
        return NoFix(fix.time_us, "held back: the landmarks disagree with the autopilot's "
                     f"attitude ({self._streak} of {self._confirm} frames in a row)", fix.notes)


#: Two rejections of the autopilot's attitude further apart than this are not "in a row".
REJECT_WINDOW_US = 200_000
