"""``companion run`` on a recording: the recording's camera, its frames on the companion's
clock, and (on request) the attitude of its ``truth_pose.csv`` instead of the autopilot's.

A recorded stream, an OTB folder or a video file carries the times it was recorded with
(0 at its start).  Everything downstream runs on the companion's monotonic clock: the
bridge refuses a fix whose capture time is older than ``mavlink.max_fix_age_ms``
(``mavlink_bridge/messages.py fix_problem``) and the attitude of a frame is looked up at
its capture time (``companion.sensors.SensorHistory``).  :class:`OnCompanionClock`
therefore stamps each frame with the companion clock at the moment the source delivers
it (after the source's own pacing), as a live camera's frames are, and remembers which
recorded frame that was.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import OrderedDict
from pathlib import Path

from companion.core.stream_format import TruthPose
from companion.core.stream_io import read_truth_pose
from companion.errors import InputError
from companion.landmarks.geodesy import LocalFrame
from companion.sources.base import Frame, FrameSource, monotonic_us
from companion.sources.files import RecordedStreamSource
from mavlink_bridge.fake_drift import AttitudeDrift, AttitudeErrorConfig
from tracker.camera import CameraModel
from tracker.pose.types import AttitudeSample

log = logging.getLogger(__name__)

#: How many delivered frames :class:`OnCompanionClock` remembers (a few seconds' worth).
REMEMBER = 512
#: Source kinds whose frames carry recorded times, not the companion's clock.
RECORDED_KINDS = ("stream", "otb", "video")


class OnCompanionClock:
    """A recorded source whose frames are stamped with the companion's clock on delivery.

    ``recorded(t_us)`` gives back (the source's frame index, the recorded time) of a
    frame by its new stamp, for the last :data:`REMEMBER` frames.
    """

    def __init__(self, source: FrameSource) -> None:
        self.source = source
        self._seen: OrderedDict[int, tuple[int, int]] = OrderedDict()
        self.last_us: int | None = None

    @property
    def status(self) -> object:
        return getattr(self.source, "status", None)

    async def recv(self) -> Frame:
        frame = await self.source.recv()
        t_us = max(monotonic_us(), (self.last_us or 0) + 1)  # strictly increasing
        self.remember(t_us, frame.index, frame.t_us)
        return dataclasses.replace(frame, t_us=t_us)

    def remember(self, t_us: int, index: int, recorded_us: int) -> None:
        """Note that the frame stamped ``t_us`` is recorded frame ``index`` of
        ``recorded_us``."""
        self._seen[t_us] = (index, recorded_us)
        while len(self._seen) > REMEMBER:
            self._seen.popitem(last=False)
        self.last_us = t_us

    def recorded(self, t_us: int) -> tuple[int, int] | None:
        return self._seen.get(t_us)

    def close(self) -> None:
        close = getattr(self.source, "close", None)
        if callable(close):
            close()


def recording_camera(configured: CameraModel, source: FrameSource, spec: str) -> CameraModel:
    """A recorded stream's own ``[camera]`` (with a warning when the configuration's
    differs); the configured camera for any other source."""
    if not isinstance(source, RecordedStreamSource):
        return configured
    recorded = source.meta.camera
    if recorded != configured:
        changed = [f"{name} {getattr(configured, name)} -> {getattr(recorded, name)}"
                   for name in ("width", "height", "fx", "fy", "cx", "cy", "distortion",
                                "mount_rpy_deg")
                   if getattr(configured, name) != getattr(recorded, name)]
        log.warning("%s: the stream was recorded with another camera than [camera]: "
                    "solving with the stream's (%s)", spec, "; ".join(changed))
    return recorded


class RecordedTruth:
    """The recorded vehicle pose (``truth_pose.csv``) of a frame delivered through
    :class:`OnCompanionClock`, its position placed in the flight's NED frame (the
    stream's ``[origin]`` may differ from the EKF origin)."""

    def __init__(self, clock: OnCompanionClock, source: RecordedStreamSource,
                 flight_origin: LocalFrame) -> None:
        self.clock = clock
        self.folder = source.folder
        self.poses: dict[int, tuple[int, TruthPose]] = read_truth_pose(source.folder)
        self._span = max(self.poses, default=0) + 1
        o = source.meta.origin
        self._stream = None if o is None else LocalFrame(o.lat, o.lon, o.alt_m)
        self._flight = flight_origin

    def __bool__(self) -> bool:
        return bool(self.poses)

    def pose_at(self, t_us: int) -> tuple[int, TruthPose] | None:
        """(recorded time, pose) of the frame stamped ``t_us``, None when unknown."""
        seen = self.clock.recorded(t_us)
        entry = None if seen is None else self.poses.get(seen[0] % self._span)
        return None if seen is None or entry is None else (seen[1], entry[1])

    def position(self, t_us: int) -> tuple[float, float, float] | None:
        """The frame's true position in the flight's NED frame."""
        found = self.pose_at(t_us)
        if found is None:
            return None
        p = found[1]
        return self.to_flight((p.north_m, p.east_m, p.down_m))

    def to_flight(self, ned: tuple[float, float, float]) -> tuple[float, float, float]:
        """A position of the stream's NED frame in the flight's."""
        if self._stream is None or self._stream == self._flight:
            return ned
        lat, lon, alt = self._stream.to_wgs84(*ned)
        n, e, d = (float(v) for v in self._flight.to_ned(lat, lon, alt))
        return (n, e, d)


class TruthAttitude:
    """Frames' attitude from a recorded stream's ``truth_pose.csv``, plus the error an
    autopilot's estimate has (``AttitudeErrorConfig`` defaults: a real EKF's 1 deg
    roll/pitch and 3 deg yaw Gauss-Markov error with a 1 deg/min yaw drift), for checking a
    recording offline without an autopilot."""

    def __init__(self, truth: RecordedTruth, error: AttitudeErrorConfig | None = None,
                 seed: int = 0) -> None:
        if not truth:
            raise InputError(f"{truth.folder}: --truth-attitude: the stream has no "
                             "truth_pose.csv")
        self.truth = truth
        self.config = error or AttitudeErrorConfig()
        self.drift = AttitudeDrift(self.config, seed)
        # the error's clock starts with the recording (a live recording keeps the recorder's
        # monotonic times: its yaw drift must not count the recorder's uptime)
        self.t0_us = min((t for t, _ in truth.poses.values()), default=0)
        log.warning("attitude from %s with a simulated autopilot error (1-sigma %g deg "
                    "roll/pitch, %g deg yaw, correlation %g s), not from the autopilot",
                    Path(truth.folder) / "truth_pose.csv", self.config.roll_pitch_sigma_deg,
                    self.config.yaw_sigma_deg, self.config.correlation_s)

    def last_us(self) -> int | None:
        return self.truth.clock.last_us

    def at(self, t_us: int, max_gap_us: int = 100_000) -> AttitudeSample | None:
        """The recorded frame's true attitude plus the error at its recorded time."""
        found = self.truth.pose_at(t_us)
        if found is None:
            return None
        recorded_us, pose = found
        er, ep, ey = self.drift.error((recorded_us - self.t0_us) / 1e6)
        return AttitudeSample(t_us, pose.roll_rad + er, pose.pitch_rad + ep,
                              math.remainder(pose.yaw_rad + ey, math.tau))
