"""Per-frame perception: acquire landmarks, track them, and solve the vehicle's pose.

Runs in the pipeline's worker thread (synchronous, no asyncio).  For each frame:

1. every live track is updated by its own tracker (the adaptive particle filter); a track
   whose tracker reports the target lost is dropped, with an event;
2. its four corners are refined by aligning the landmark's appearance reference onto the
   frame (ECC), started from the last homography moved with the tracker's box -- the
   tracker says *where*, the alignment says *exactly where the corners are*;
3. the observations go to the pose solver with the autopilot's attitude, height and range
   at the frame's capture time (``sensors``, :class:`companion.sensors.SensorHistory` in a
   flight); a fix for which the solver rejected the attitude is an event
   ("attitude prior rejected") and counted in ``attitude_rejections``.

:meth:`Perception.housekeeping` (after the fix is out, on the pipeline's background
thread, possibly while :meth:`Perception.process` works on a later frame) looks for map
landmarks that are not tracked, by their appearance references (ORB features + verified
homography) every ``acquire_every_frames`` frames and at once whenever nothing is tracked,
and by prediction from the frame's fix.  A hit is a started tracker handed over under a
lock; the next ``process`` adopts it.  Nothing else is shared between the two threads
but read-only data (references, map, configuration) and that lock-guarded hand-over.

Algorithms live in ``tracker/``; this module only keeps state and glues them together.
"""

from __future__ import annotations

import concurrent.futures
import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from companion.acquisition import TRACK_MIN_CORRELATION, Acquisition
from companion.app import Frame, FrameResult
from companion.corner_noise import CornerNoise
from companion.fixgate import FixGate, FixGateConfig
from companion.perception_types import (
    DetectFn,
    PerceptionConfig,
    SideSensors,
    Start,
    Track,
    TrackView,
)
from tracker import TrackerConfig
from tracker.acquire import (
    AcquireConfig,
    Reference,
    ReferenceMatcher,
    homography_to,
    project_corners,
)
from tracker.boxes import (
    box_corners,
    in_view_share,
    inside,
    saturated_share,
)
from tracker.camera import CameraModel, Rectifier
from tracker.edge_align import align_cut, box_shift, shifted
from tracker.pose.attitude_bias import AttitudeBias
from tracker.pose.config import PoseConfig
from tracker.pose.solve import solve_pose
from tracker.pose.types import (
    MapLandmark,
    NoFix,
    Observation,
    PoseFix,
)
from tracker.types import Box, TrackResult
from tracker.verify import check_appearance, quad_iou

FloatArray = npt.NDArray[np.float64]


#: How many frames' fixes are kept for housekeeping to look up.
RECENT_FIXES = 8



def moved_to_box(ref: Reference, hom: FloatArray, box: Box) -> FloatArray:
    """``hom`` moved so that the outline it projects is centred on the tracker's ``box``
    (a track without corners this frame: its last homography, where the tracker is)."""
    x, y, w, h = box
    dx, dy = np.array([x + w / 2, y + h / 2]) - project_corners(ref, hom).mean(axis=0)
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]]) @ hom


class Perception(Acquisition):
    """The pipeline's :class:`~companion.app.FrameProcessor` (acquisition:
    :class:`companion.acquisition.Acquisition`)."""

    def __init__(self, camera: CameraModel, landmarks: Sequence[MapLandmark],
                 references: Mapping[str, npt.NDArray[np.uint8]],
                 sensors: Callable[[int], SideSensors] = lambda _t_us: SideSensors(),
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
        self.tracker_config = tracker_config
        self.pose_config = pose_config or PoseConfig()
        self.sensors = sensors
        self.noise = CornerNoise(self.camera, self.config, self.pose_config, self._rectify,
                                 self.landmarks)
        self.matcher = ReferenceMatcher(acquire_config)  # housekeeping's
        self.unmatchable: dict[str, str] = {}
        for lid, image in references.items():
            try:
                self.matcher.add(lid, image)
            except ValueError as err:
                self.unmatchable[lid] = str(err)
        self._recover_matcher = self.matcher.sibling()  # process's
        self._recover_lock = threading.Lock()  # tracks may recover corners on two threads
        self._pool = concurrent.futures.ThreadPoolExecutor(1, "companion-tracks") \
            if self.config.parallel_tracks else None
        self.tracks: dict[str, Track] = {}
        self.gate = FixGate(gate_config or FixGateConfig())
        # handed from housekeeping to process, under the lock
        self._lock = threading.Lock()
        self._events_next: list[dict[str, Any]] = []
        self._pending: list[Start] = []
        self._fixes: dict[int, PoseFix] = {}  # frame index -> its fix (the last few)
        self._checked: dict[str, float] = {}  # this frame's appearance checks (correlation)
        self._rectified: dict[int, npt.NDArray[np.uint8]] = {}  # the same, rectified frames
        # housekeeping's own
        self._last_fix_us = -(2**62)
        self._acquired_frame = -(2**62)
        self._search_turn = 0
        self._lost_turn = False  # features (first) and the lost search take turns
        self._search_next = False  # the template search's turn after a fruitless detector
        self.detect = detect
        self._seed = seed
        #: fixes for which the autopilot's attitude disagreed with the landmarks' (not used)
        self.attitude_rejections = 0
        #: the autopilot's attitude error learnt from the fixes (tracker/pose/attitude_bias.py)
        self.attitude_bias = AttitudeBias(self.pose_config) \
            if self.pose_config.learn_attitude_bias else None
        self._frames = 0
        self._light_level: float | None = None

    def process(self, frame: Frame) -> FrameResult:
        """Track and solve: one frame in, tracks and maybe a fix out.

        Acquisition of new landmarks waits for :meth:`housekeeping`, after the fix is on
        the wire, so it never adds to the capture -> fix latency; what it started is
        adopted here.
        """
        image = frame.image
        events = self._adopt()
        if image.shape[:2] != (self.camera.height, self.camera.width):
            return FrameResult(frame.index, frame.t_us, bad_frame=True,
                               no_fix_reason=f"frame {image.shape[1]}x{image.shape[0]} is "
                               f"not the camera's {self.camera.width}x{self.camera.height}")
        if self._rectify is not None:
            image = self._rectify(image)
            with self._lock:  # for this frame's housekeeping (which may skip frames)
                self._rectified[frame.index] = image
                for old in [i for i in self._rectified if i <= frame.index - RECENT_FIXES]:
                    del self._rectified[old]
        # each track's appearance check is due every ``verify_every_frames``, the tracks'
        # checks on different frames (issue 23: not every track's on one frame), and all
        # at once on a light step; a track is checked right after its update, on its thread
        stepped = self._light_step(image)
        tracks = list(self.tracks.values())
        every = self.config.verify_every_frames
        checks = [stepped or (self._frames + i) % every == 0 for i in range(len(tracks))]
        for track, alive in zip(tracks, self._update_tracks(tracks, image, checks),
                                strict=True):
            if not alive:
                del self.tracks[track.landmark_id]
                events.append({"event": "lost", "landmark": track.landmark_id})
        if any(checks):
            events += self._verify_tracks()
        self._frames += 1
        return self._solve(frame, events)

    def _light_step(self, image: npt.NDArray[np.uint8]) -> bool:
        """True when the frame's mean grey level jumped by ``light_step_ratio`` or more
        since the last frame (housekeeping then acquires at once)."""
        level = max(float(image[::8, ::8].mean()), 1.0)
        last, self._light_level = self._light_level, level
        if last is None or max(level / last, last / level) < self.config.light_step_ratio:
            return False
        self._acquired_frame = -(2**62)  # acquisition is due now
        return True

    def _check_track(self, track: Track, image: npt.NDArray[np.uint8]) -> None:
        """Check the track's landmark is still where its homography says, by its warped
        appearance (its correlation goes to ``_checked``; the track's own state only)."""
        ref = self.matcher.references[track.landmark_id]
        hom = track.homography
        if hom is not None and track.corners is None:
            hom = moved_to_box(ref, hom, track.box)  # no corners this frame: at the box
        ncc, fit = (0.0, None) if hom is None else check_appearance(ref, image, hom)
        track.fit_sigma = fit if self.config.corner_sigma_from_fit else None
        track.verify_failures = 0 if ncc >= self.config.track_appearance_ncc \
            else track.verify_failures + 1
        self._checked[track.landmark_id] = ncc  # one key per track: no two threads share one

    def _verify_tracks(self, image: npt.NDArray[np.uint8] | None = None
                       ) -> list[dict[str, Any]]:
        """Check every track on ``image`` (None: :meth:`process` has, in the track updates);
        a track that failed is left out of fixes, dropped after repeated failures."""
        if image is not None:
            for track in list(self.tracks.values()):
                self._check_track(track, image)
        events: list[dict[str, Any]] = []
        checked, self._checked = self._checked, {}
        for track in list(self.tracks.values()):
            if track.verify_failures >= self.config.max_verify_failures:
                del self.tracks[track.landmark_id]
                ncc = checked.get(track.landmark_id, 0.0)
                events.append({"event": "lost", "landmark": track.landmark_id,
                               "why": f"appearance no longer there (correlation {ncc:.2f})"})
        return events

    def close(self) -> None:
        """Stop the track-update thread (the pipeline calls this once it has stopped)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)

    def _update_tracks(self, tracks: list[Track], image: npt.NDArray[np.uint8],
                       checks: Sequence[bool] = ()) -> list[bool]:
        """Update every track (and check the appearance of those whose ``checks`` entry is
        true: :meth:`_check_track`); with two or more, every other one on the second
        thread.  Each track touches only its own state."""
        due = [bool(c) for c in checks] or [False] * len(tracks)
        if self._pool is None or len(tracks) < 2:
            return [self._update_track(t, image, c) for t, c in zip(tracks, due, strict=True)]
        there = [self._pool.submit(self._update_track, t, image, c)
                 for t, c in zip(tracks[::2], due[::2], strict=True)]
        here = [self._update_track(t, image, c)
                for t, c in zip(tracks[1::2], due[1::2], strict=True)]
        there_ok = [f.result() for f in there]
        return [there_ok[i // 2] if i % 2 == 0 else here[i // 2] for i in range(len(tracks))]

    def _adopt(self) -> list[dict[str, Any]]:
        """Take over the trackers housekeeping started (and its events)."""
        with self._lock:
            events, self._events_next = self._events_next, []
            pending, self._pending = self._pending, []
        for start in pending:
            lid = start.track.landmark_id
            if lid not in self.tracks and len(self.tracks) < self.config.max_tracks:
                self.tracks[lid] = start.track
                events.append(start.event)
        return events

    def housekeeping(self, frame: Frame) -> None:
        """Look for untracked landmarks (feature matching now and then; prediction from
        this frame's fix); what is found is tracked from the next ``process`` on.

        Safe to run while :meth:`process` works on a later frame (see the module's notes).
        """
        if frame.image.shape[:2] != (self.camera.height, self.camera.width):
            return
        with self._lock:
            fix = self._fixes.get(frame.index)
            rectified = self._rectified.pop(frame.index, None)
            for old in [i for i in self._rectified if i < frame.index]:
                del self._rectified[old]
        image = self._rectified_image(frame) if rectified is None else rectified
        starts: list[Start] = []
        if fix is not None:
            self._last_fix_us = fix.time_us
        acquire = self._should_acquire(frame)
        lost = fix is None and frame.t_us - self._last_fix_us > self.config.search_after_s * 1e6
        # While tracks run, one heavy step per call (they take turns, issue 23): a call that
        # runs several holds a one-core board's next frame up by their sum.  With no track
        # the frames carry no fix to delay: then all at once, for the quickest start (taking
        # turns there too lost sitl_tests/test_one_landmark.py's box track for 1/3 of its
        # frames: re-acquired by the template search alone, it failed its checks).
        spread = bool(self.tracks)
        if acquire and lost and spread:
            self._lost_turn = not self._lost_turn
            acquire, lost = self._lost_turn, not self._lost_turn
        if acquire:
            self._acquired_frame = frame.index
            starts += self._acquire(image)
        if fix is not None:
            starts += self._predict_acquire(image, fix, starts)
        elif lost:
            starts += self._find_while_lost(image, spread)
        if starts:
            with self._lock:
                self._pending += starts

    def _rectified_image(self, frame: Frame) -> npt.NDArray[np.uint8]:
        """The frame as tracking sees it: rectified for a distorted camera.  Housekeeping
        reuses what ``process`` rectified; this is for a frame ``process`` has let go of
        (housekeeping lagging more than ``RECENT_FIXES`` frames) or never saw."""
        return frame.image if self._rectify is None else self._rectify(frame.image)

    # -- tracking ---------------------------------------------------------------------

    def _update_track(self, track: Track, image: npt.NDArray[np.uint8],
                      check: bool = False) -> bool:
        alive = self._follow(track, image)
        if alive and check:
            self._check_track(track, image)
        return alive

    def _follow(self, track: Track, image: npt.NDArray[np.uint8]) -> bool:
        """The tracker's update and the corners' alignment; False when the track is lost."""
        result: TrackResult = track.tracker.update(image)
        if result.box is None or result.confidence < self.config.min_track_confidence:
            return False
        last_box, track.box = track.box, result.box
        track.confidence, track.features = result.confidence, result.features
        track.corners = None
        if not self.config.refine_corners:
            return True
        if track.homography is not None:
            predicted = track.homography  # landmarks move a few px a frame: ECC takes that up
            aligned = self._align_cut(track, image, predicted, last_box) if self._is_cut(
                track.landmark_id, predicted) else self._align(track, image, predicted)
            track.homography = predicted if aligned is None else aligned
            track.misses = 0 if aligned is not None else track.misses + 1
            if aligned is not None:
                track.corners = project_corners(self.matcher.references[track.landmark_id],
                                                aligned)
        if track.homography is None or track.misses >= self.config.max_corner_misses:
            self._recover_corners(track, image)
        track.saturated = 0.0 if track.corners is None else saturated_share(image, track.corners)
        return True

    def _align(self, track: Track, image: npt.NDArray[np.uint8], hom: FloatArray,
               verify: bool = False) -> FloatArray | None:
        """ECC alignment of the reference on the tracker's best colour feature (grey levels
        for a grey target), kept only if it agrees with the tracker's box."""
        ref = self.matcher.references[track.landmark_id]
        aligned = self._ecc(ref, image, hom, verify, track.align_weights)
        box = track.box
        if aligned is None:
            return None
        corners = project_corners(ref, aligned)
        x, y, w, h = box
        if verify:  # from the box itself: its centre must lie on the plate found
            outline = corners.astype(np.float32).reshape(-1, 1, 2)
            on = cv2.pointPolygonTest(outline, (x + w / 2, y + h / 2), False) >= 0
            return aligned if on else None
        # the outline predicted (the last one, moved with the tracker's box) against the
        # outline found: a rotated plate's outline fills its axis-aligned box poorly, so
        # outlines are compared, not boxes
        predicted = project_corners(ref, hom)
        predicted = predicted + (np.array([x + w / 2, y + h / 2]) - predicted.mean(axis=0))
        if quad_iou(corners, predicted) < self.config.min_corner_agreement:
            return None  # the alignment wandered off: keep the box, drop the corners
        return aligned

    def _is_cut(self, landmark_id: str, hom: FloatArray) -> bool:
        """Is the outline ``hom`` projects cut by the image's edge below
        ``min_corner_in_view`` (its tracker's box then holds only the part in view)?"""
        outline = project_corners(self.matcher.references[landmark_id], hom)
        share = in_view_share(outline, self.camera.width, self.camera.height)
        return share < self.config.min_corner_in_view

    def _align_cut(self, track: Track, image: npt.NDArray[np.uint8], hom: FloatArray,
                   last_box: Box) -> FloatArray | None:
        """A cut plate's homography moved by the affine alignment of its part in view
        (tracker/edge_align.py): a full alignment on a corner region bends the rest.  It
        starts moved as the tracker's box moved since ``last_box`` (its edges inside the
        image) when it does not align where it was: a plate sliding 10-20 px a frame is out
        of the affine alignment's reach (and a still one's box jitters by a pixel)."""
        ref = self.matcher.references[track.landmark_id]
        dx, dy = box_shift(last_box, track.box, self.camera.width, self.camera.height)
        for start in (hom, shifted(hom, dx, dy)) if max(abs(dx), abs(dy)) > 2.0 else (hom,):
            aligned = align_cut(ref, image, start, self.config.ecc_iterations,
                                TRACK_MIN_CORRELATION, track.align_weights)
            if aligned is not None:
                return aligned
        return None

    def _recover_corners(self, track: Track, image: npt.NDArray[np.uint8]) -> None:
        """Get the homography back: align the reference onto the tracked box (held to
        ``verify_correlation``), else re-match its features around the box.  Alignment
        first: it is cheaper, and finds plates too small or plain for feature matching."""
        lid = track.landmark_id
        ref = self.matcher.references[lid]
        aligned = self._align(track, image, homography_to(ref, box_corners(track.box)),
                              verify=True)
        if aligned is not None:
            track.homography, track.corners = aligned, project_corners(ref, aligned)
            track.misses = 0
            return
        x, y, w, h = track.box
        roi = (x - 0.5 * w, y - 0.5 * h, 2.0 * w, 2.0 * h)
        with self._recover_lock:
            found = self._recover_matcher.find(image, [lid], roi=roi)
        if found:
            track.homography, track.corners, track.misses = (found[0].homography,
                                                             found[0].corners_px, 0)
        else:
            track.homography = None

    # -- acquisition ------------------------------------------------------------------

    def _distance(self, fix: PoseFix) -> float:
        """Mean distance (m) from the fix to the landmarks it used."""
        pos = np.asarray(fix.position_ned_m)
        used = [lm for lm in self.landmarks if lm.landmark_id in fix.landmark_ids]
        return float(np.mean([np.linalg.norm(pos - np.asarray(lm.position_ned_m))
                              for lm in used])) if used else 0.0

    # -- pose -------------------------------------------------------------------------

    def observations(self, frame_index: int) -> list[Observation]:
        """One observation per live track (corners when the alignment holds).

        A plate cut by the image's edge (less than ``min_corner_in_view`` of it in view)
        gives the corners its outline puts inside the image by ``EDGE_MARGIN_PX``
        (:mod:`companion.corner_noise`) as
        measured (``Observation.corners_measured``); the ones outside are extrapolations,
        not observations.  Their sigma grows as the part in view shrinks (:meth:`CornerNoise.cut`).
        When some tracks have corners, box-only tracks are left out: a box centre is not
        the landmark's centre under perspective, and mixing it in costs more than it adds.
        Without corners, a box that reaches out of the image is left out too: its centre is
        off its plate's by up to half the part out of view.
        """
        out = []
        size = (self.camera.width, self.camera.height)
        cfg = self.config
        tracks = [t for t in self.tracks.values() if t.verify_failures == 0]
        usable = {t.landmark_id: self.noise.cut(t) for t in tracks
                  if t.corners is not None and t.saturated <= cfg.max_corner_saturated}
        # a cut plate's fit sigma is its whole outline's (the extrapolated corners' too):
        # not held against the size model, but stated (the larger of the two, CornerNoise.sigma)
        usable = {lid: cut for lid, cut in usable.items() if cut is not None
                  and (cut[0] is not None or self.noise.fits(self.tracks[lid]))}
        if usable:
            tracks = [t for t in tracks if t.landmark_id in usable]
        else:  # boxes only: a box reaching out of the image is not centred on its plate
            tracks = [t for t in tracks if inside(box_corners(t.box), *size, margin=1.0)]
        for t in tracks:
            x, y, w, h = t.box
            cut = usable.get(t.landmark_id)
            corners = None if t.corners is None or cut is None else tuple(
                (float(u), float(v)) for u, v in t.corners)
            centre = ((x + w / 2, y + h / 2) if corners is None
                      else tuple(float(c) for c in np.mean(corners, axis=0)))
            stretch = 1.0 if corners is None else self.noise.stretch(corners)  # once a plate
            scale = None if corners is None else self.config.corner_scale_sigma_px * stretch
            sigma = self.noise.sigma(corners, stretch, t.fit_sigma)
            measured, grow = (None, 1.0) if cut is None else cut
            out.append(Observation(centre_px=(float(centre[0]), float(centre[1])),
                                   box_wh_px=(w, h), confidence=t.confidence,
                                   landmark_id=t.landmark_id, corners_px=corners,
                                   frame_index=frame_index,
                                   corner_sigma_px=None if sigma is None else sigma * grow,
                                   corner_scale_sigma_px=scale, corners_measured=measured))
        return out

    def _drop_rejected(self, observations: Sequence[Observation], fix: PoseFix
                       ) -> list[dict[str, Any]]:
        """Count, per track, the fixes in a row that left its corners out; drop a track at
        ``max_pose_rejections`` (housekeeping then acquires it afresh)."""
        limit = self.config.max_pose_rejections
        events: list[dict[str, Any]] = []
        for o in observations:
            track = None if o.landmark_id is None else self.tracks.get(o.landmark_id)
            if track is None or o.corners_px is None:
                continue
            used = o.landmark_id in fix.landmark_ids
            track.pose_rejections = 0 if used else track.pose_rejections + 1
            if limit and track.pose_rejections >= limit:
                del self.tracks[track.landmark_id]
                events.append({"event": "lost", "landmark": track.landmark_id,
                               "why": f"its corners left out of {limit} fixes in a row"})
        return events

    def _solve(self, frame: Frame, events: list[dict[str, Any]]) -> FrameResult:
        tracks = tuple(TrackView.of(t) for t in self.tracks.values())
        if not self.tracks:
            return FrameResult(frame.index, frame.t_us, tracks, None, "nothing tracked",
                               tuple(events))
        particles = {t.landmark_id: t.tracker.particle_centres for t in self.tracks.values()}
        side = self.sensors(frame.t_us)
        bias = self.attitude_bias
        attitude = side.attitude if bias is None else bias.correct(side.attitude)
        observations = [self.noise.floor(o, self.tracks)
                        for o in self.observations(frame.index)]
        fix = solve_pose(observations, self.landmarks, self.camera,
                         frame.t_us, attitude=attitude, altitude=side.altitude,
                         laser=side.laser, config=self.pose_config)
        if bias is not None:
            bias.learn(side.attitude, fix)
        if isinstance(fix, PoseFix):
            self.noise.learn(observations, fix, self.tracks)
            events += self._drop_rejected(observations, fix)
        if isinstance(fix, NoFix):
            return FrameResult(frame.index, frame.t_us, tracks, None, fix.reason, tuple(events),
                               particles=particles)
        if fix.attitude_prior == "rejected":
            self.attitude_rejections += 1
            why = next(n for n in fix.notes if n.startswith("attitude prior rejected"))
            events.append({"event": "attitude prior rejected", "detail": why,
                           "count": self.attitude_rejections})
        if not self.gate.precise(fix, self._distance(fix)):
            return FrameResult(frame.index, frame.t_us, tracks, None,
                               "held back: too vague for its distance", tuple(events),
                               particles=particles)
        if not self.gate.admit(fix):
            return FrameResult(frame.index, frame.t_us, tracks, None,
                               "held back: inconsistent with recent fixes", tuple(events),
                               particles=particles)
        with self._lock:  # for this frame's housekeeping
            self._fixes[frame.index] = fix
            for old in [i for i in self._fixes if i <= frame.index - RECENT_FIXES]:
                del self._fixes[old]
        return FrameResult(frame.index, frame.t_us, tracks, fix, None, tuple(events),
                           particles=particles)


class PerceptionWrapper:
    """Base of processors that add to what a :class:`Perception` returns (truth taggers
    of the demo, follow mode and the tests): override :meth:`process`."""

    def __init__(self, perception: Perception) -> None:
        self.perception = perception

    def process(self, frame: Frame) -> FrameResult:
        return self.perception.process(frame)

    def housekeeping(self, frame: Frame) -> None:
        self.perception.housekeeping(frame)

    def close(self) -> None:
        self.perception.close()
