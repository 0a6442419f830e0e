"""Per-frame perception: acquire landmarks, track them, and solve the vehicle's pose.

:class:`Perception` is the pipeline's :class:`~companion.app.FrameProcessor`, a thin
coordinator of its parts (docs/architecture.md, "Perception"):

* :class:`companion.tracks.TrackSet` -- the live tracks, updated each frame (the adaptive
  particle filter's box, then the corners by :class:`companion.corners.Corners`), checked
  by their appearance, dropped when lost;
* :class:`companion.acquisition.Acquisition` -- when to look for untracked landmarks, and
  the four acquirers of :mod:`companion.acquirers` that find them;
* :class:`companion.corner_noise.CornerNoise` -- the corners' stated 1-sigma;
* :class:`companion.side_sensors.SideInputs` -- the autopilot's attitude, height and range
  at the frame's capture time, the attitude corrected by the error learnt from fixes;
* :class:`companion.fixgate.FixGate` -- which solved fixes go out.

Threads.  :meth:`Perception.process` runs on the pipeline's worker thread: it adopts the
tracks housekeeping started, updates the tracks (on two threads: the track set's), solves
the pose and gates the fix.  :meth:`Perception.housekeeping` runs after the fix is out, on
the pipeline's background lane, possibly while ``process`` works on a later frame: it
looks for untracked landmarks.  The two share only, each under a lock:

* the track set's snapshot and hand-over (housekeeping sees which landmarks are taken,
  never the tracks; what it starts, ``process`` adopts: :mod:`companion.tracks`);
* :class:`FrameCache`, the last few frames' fixes and rectified images, put by
  ``process`` for housekeeping to take, and a light step's "acquire now".

Everything else shared (references, map, configuration) is read-only; every other piece
of state belongs to one thread.  The JSON of a result is built by
:mod:`companion.reporting`; the algorithms live in ``tracker/``.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from companion.acquirers import (
    DetectorAcquirer,
    FeatureAcquirer,
    PredictionAcquirer,
    SearchAcquirer,
    Sighting,
    Starter,
)
from companion.acquisition import Acquisition
from companion.app import Frame, FrameResult
from companion.corner_noise import CornerNoise, cornered
from companion.corners import Corners, grey_aligned
from companion.ego_motion import TurnPredictor
from companion.fixgate import FixGate, FixGateConfig
from companion.perception_types import DetectFn, PerceptionConfig, Track
from companion.side_sensors import (
    PoseGuess,
    SensorReader,
    SideInputs,
    SideSensors,
    guess_of,
    no_sensors,
)
from companion.tracks import TrackSet, observations
from tracker import TrackerConfig
from tracker.acquire import AcquireConfig, ReferenceMatcher
from tracker.camera import CameraModel, Rectifier
from tracker.pose.config import PoseConfig
from tracker.pose.solve import solve_pose
from tracker.pose.types import MapLandmark, NoFix, Observation, PoseFix

__all__ = ["DetectFn", "Perception", "PerceptionConfig", "SideSensors"]

#: How many frames' fixes are kept for housekeeping to look up.
RECENT_FIXES = 8

Image = npt.NDArray[np.uint8]


class FrameCache:
    """What ``process`` leaves for a frame's housekeeping, under a lock: the frame's fix,
    its rectified image (the last ``RECENT_FIXES`` frames' each) and whether a light step
    made acquisition due at once."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._fixes: dict[int, PoseFix] = {}  # frame index -> its fix (the last few)
        self._rectified: dict[int, Image] = {}  # the same, rectified frames
        self._acquire_now = False

    def put_rectified(self, index: int, image: Image) -> None:
        with self._lock:
            self._rectified[index] = image
            for old in [i for i in self._rectified if i <= index - RECENT_FIXES]:
                del self._rectified[old]

    def put_fix(self, index: int, fix: PoseFix) -> None:
        with self._lock:
            self._fixes[index] = fix
            for old in [i for i in self._fixes if i <= index - RECENT_FIXES]:
                del self._fixes[old]

    def acquire_now(self) -> None:
        with self._lock:
            self._acquire_now = True

    def take(self, index: int) -> tuple[PoseFix | None, Image | None, bool]:
        """Frame ``index``'s fix and rectified image (None: none kept), and whether
        acquisition is due at once; earlier frames' images are let go."""
        with self._lock:
            fix = self._fixes.get(index)
            rectified = self._rectified.pop(index, None)
            for old in [i for i in self._rectified if i < index]:
                del self._rectified[old]
            now, self._acquire_now = self._acquire_now, False
        return fix, rectified, now


class Perception:
    """Tracks map landmarks in each frame and solves the vehicle's pose from them."""

    def __init__(self, camera: CameraModel, landmarks: Sequence[MapLandmark],
                 references: Mapping[str, npt.NDArray[np.uint8]],
                 sensors: SensorReader = no_sensors,
                 config: PerceptionConfig | None = None,
                 tracker_config: TrackerConfig | None = None,
                 pose_config: PoseConfig | None = None,
                 acquire_config: AcquireConfig | None = None,
                 gate_config: FixGateConfig | None = None, seed: int = 0,
                 detect: DetectFn | None = None) -> None:
        # a distorted camera's frames are rectified first: tracking, alignment and the pose
        # then work in the pinhole image of ``self.camera`` (same intrinsics)
        self._rectify = Rectifier(camera) if any(camera.distortion) else None
        self.camera = camera if self._rectify is None else self._rectify.camera
        self.landmarks = list(landmarks)
        self.config = config or PerceptionConfig()
        self.pose_config = pose_config or PoseConfig()
        self.side = SideInputs(sensors, self.pose_config)
        self.matcher = ReferenceMatcher(acquire_config)  # housekeeping's
        self.unmatchable: dict[str, str] = {}
        for lid, image in references.items():
            try:
                self.matcher.add(lid, image)
            except ValueError as err:
                self.unmatchable[lid] = str(err)
        refs = self.matcher.references
        self.noise = CornerNoise(self.camera, self.config, self.pose_config, self._rectify,
                                 self.landmarks, frozenset(
                                     lid for lid, ref in refs.items()
                                     if grey_aligned(self.config, ref)))
        self.trackset = TrackSet(self.config, Corners(self.camera, self.config, refs,
                                                      self.matcher.sibling()))
        starter = Starter(refs, self.config, tracker_config, seed)
        self.acquisition = Acquisition(
            self.config, starter, FeatureAcquirer(self.matcher, starter),
            PredictionAcquirer(self.camera, self.landmarks, starter), SearchAcquirer(starter),
            None if detect is None else DetectorAcquirer(detect, self.landmarks, starter))
        self.gate = FixGate(gate_config or FixGateConfig())
        self._cache = FrameCache()
        self._light_level: float | None = None  # the worker thread's
        self._turn = TurnPredictor(self.camera, self.config.predict_turn_deg)

    @property
    def tracks(self) -> Mapping[str, Track]:
        """The live tracks by landmark id: the worker thread's (read them from there, or
        between frames); a result carries frozen copies (``FrameResult.tracks``)."""
        return self.trackset.live

    @property
    def attitude_rejections(self) -> int:
        """Fixes for which the autopilot's attitude disagreed with the landmarks' (not
        used: an event each)."""
        return self.side.attitude_rejections

    def process(self, frame: Frame) -> FrameResult:
        """Track and solve: one frame in, tracks and maybe a fix out.

        Acquisition of new landmarks waits for :meth:`housekeeping`, after the fix is on
        the wire, so it never adds to the capture -> fix latency; what it started is
        adopted here.
        """
        image = frame.image
        self.noise.lossy = frame.lossy
        events = self.trackset.adopt()
        if image.shape[:2] != (self.camera.height, self.camera.width):
            return FrameResult(frame.index, frame.t_us, bad_frame=True,
                               no_fix_reason=f"frame {image.shape[1]}x{image.shape[0]} is "
                               f"not the camera's {self.camera.width}x{self.camera.height}")
        if self._rectify is not None:
            image = self._rectify(image)
            self._cache.put_rectified(frame.index, image)  # housekeeping may skip frames
        # the side sensors are read once a frame: here when the turn needs them, else by
        # the solve (only with something tracked)
        sensed = self.side.at(frame.t_us) if self._turn.enabled else None
        motion = None if sensed is None else self._turn.motion(sensed[0].attitude)
        events += self.trackset.update(image, check_all=self._light_step(image), motion=motion)
        return self._solve(frame, events, sensed)

    def _light_step(self, image: Image) -> bool:
        """True when the frame's mean grey level jumped by ``light_step_ratio`` or more
        since the last frame (housekeeping then acquires at once)."""
        level = max(float(image[::8, ::8].mean()), 1.0)
        last, self._light_level = self._light_level, level
        if last is None or max(level / last, last / level) < self.config.light_step_ratio:
            return False
        self._cache.acquire_now()
        return True

    def housekeeping(self, frame: Frame) -> None:
        """Look for untracked landmarks (feature matching now and then; prediction from
        this frame's fix); what is found is tracked from the next ``process`` on.

        Safe to run while :meth:`process` works on a later frame (see the module's notes).
        """
        if frame.image.shape[:2] != (self.camera.height, self.camera.width):
            return
        fix, rectified, now = self._cache.take(frame.index)
        if now:
            self.acquisition.due_now()
        image = self._rectified_image(frame) if rectified is None else rectified
        guess = None if fix is not None else self.guess(frame.t_us)
        sight = Sighting(image, self.trackset.snapshot(), fix, guess)
        starts = self.acquisition.run(frame.index, frame.t_us, sight)
        if starts:
            self.trackset.hand_over(starts)

    def guess(self, t_us: int) -> PoseGuess | None:
        """Where the autopilot believes the vehicle is at ``t_us``, with its attitude
        corrected by the error learnt from the fixes (``pose.learn_attitude_bias``): what
        acquisition predicts plates from while no fix comes (a 3 deg yaw error alone moves a
        plate ~27 px, past ``max_guess_error_px``)."""
        return guess_of(self.side.at(t_us)[1])

    def _rectified_image(self, frame: Frame) -> Image:
        """The frame as tracking sees it: rectified for a distorted camera.  Housekeeping
        reuses what ``process`` rectified; this is for a frame ``process`` has let go of
        (housekeeping lagging more than ``RECENT_FIXES`` frames) or never saw."""
        return frame.image if self._rectify is None else self._rectify(frame.image)

    def close(self) -> None:
        """Stop the track-update thread (the pipeline calls this once it has stopped)."""
        self.trackset.close()

    def observations(self, frame_index: int) -> list[Observation]:
        """One observation per live track (:func:`companion.tracks.observations`)."""
        return observations(self.tracks, self.noise, self.config, frame_index)

    def _distance(self, fix: PoseFix) -> float:
        """Mean distance (m) from the fix to the landmarks it used."""
        pos = np.asarray(fix.position_ned_m)
        used = [lm for lm in self.landmarks if lm.landmark_id in fix.landmark_ids]
        return float(np.mean([np.linalg.norm(pos - np.asarray(lm.position_ned_m))
                              for lm in used])) if used else 0.0

    def _solve(self, frame: Frame, events: list[dict[str, Any]],
               sensed: tuple[SideSensors, SideSensors] | None = None) -> FrameResult:
        """The pose from this frame's tracks; ``sensed``: the side sensors of the frame
        (as read, as the solver takes them) when :meth:`process` has read them already."""
        tracks = self.trackset.views()
        if not tracks:
            return FrameResult(frame.index, frame.t_us, tracks, None, "nothing tracked",
                               tuple(events))
        particles = self.trackset.particles()
        read, side = self.side.at(frame.t_us) if sensed is None else sensed
        observed = self.noise.alone([self.noise.floor(o, self.tracks)
                                     for o in self.observations(frame.index)], self.tracks)
        if len(cornered(observed)) == 1:
            side = self.side.for_lone_plate(read, side)
        fix = solve_pose(observed, self.landmarks, self.camera,
                         frame.t_us, attitude=side.attitude, altitude=side.altitude,
                         laser=side.laser, config=self.pose_config)
        fix, settled = self.side.settle(read, fix)
        events += settled
        if isinstance(fix, NoFix):
            events += self.trackset.drop_rejected(observed, fix)
            return FrameResult(frame.index, frame.t_us, tracks, None, fix.reason, tuple(events),
                               particles=particles)
        self.noise.learn(observed, fix, self.tracks)
        events += self.trackset.drop_rejected(observed, fix)
        why = None if self.gate.precise(fix, self._distance(fix)) \
            else "held back: too vague for its distance"
        if why is None and not self.gate.admit(fix):
            why = "held back: inconsistent with recent fixes"
        if why is not None:
            return FrameResult(frame.index, frame.t_us, tracks, None, why, tuple(events),
                               particles=particles)
        fix = self.gate.stated(fix, read.position_ned_m)
        self._cache.put_fix(frame.index, fix)  # for this frame's housekeeping
        return FrameResult(frame.index, frame.t_us, tracks, fix, None, tuple(events),
                           particles=particles)


