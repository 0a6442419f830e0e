"""Per-frame perception: acquire landmarks, track them, and solve the vehicle's pose.

Runs in the pipeline's worker thread (synchronous, no asyncio).  For each frame:

1. every live track is updated by its own tracker (the adaptive particle filter); a track
   whose tracker reports the target lost is dropped, with an event;
2. its four corners are refined by aligning the landmark's appearance reference onto the
   frame (ECC), started from the last homography moved with the tracker's box -- the
   tracker says *where*, the alignment says *exactly where the corners are*;
3. map landmarks that are not tracked are looked for by their appearance references
   (ORB features + verified homography) every ``acquire_every_frames`` frames, and at
   once whenever nothing is tracked; a hit starts a tracker;
4. the observations go to the pose solver with the latest attitude / altitude / range from
   the autopilot.

Algorithms live in ``tracker/``; this module only keeps state and glues them together.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from companion.app import Frame, FrameResult
from tracker import AdaptiveTracker, TrackerConfig
from tracker.acquire import AcquireConfig, ReferenceMatcher, refine_ecc
from tracker.camera import CameraModel
from tracker.pose.config import PoseConfig
from tracker.pose.solve import solve_pose
from tracker.pose.types import (
    AltitudeSample,
    AttitudeSample,
    MapLandmark,
    NoFix,
    Observation,
    PoseFix,
    RangeSample,
)
from tracker.types import Box, TrackResult

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PerceptionConfig:
    """How often to look for untracked landmarks and how far to trust a track."""

    acquire_every_frames: int = field(default=15, metadata={"ge": 1})
    max_tracks: int = field(default=8, metadata={"ge": 1})
    min_track_confidence: float = field(default=0.2, metadata={"ge": 0, "le": 1})
    refine_corners: bool = True
    min_corner_agreement: float = field(default=0.5, metadata={"gt": 0, "le": 1})
    ecc_iterations: int = field(default=30, metadata={"ge": 1})


@dataclass(frozen=True)
class SideSensors:
    """The autopilot's latest attitude, altitude and laser range (any may be missing)."""

    attitude: AttitudeSample | None = None
    altitude: AltitudeSample | None = None
    laser: RangeSample | None = None


@dataclass
class Track:
    """One landmark being followed."""

    landmark_id: str
    tracker: AdaptiveTracker
    box: Box
    homography: FloatArray | None
    confidence: float = 1.0
    features: tuple[int, ...] = ()
    corners: FloatArray | None = None


def box_iou(a: Box, b: Box) -> float:
    """Intersection over union of two (x, y, w, h) boxes."""
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[0] + a[2], b[0] + b[2]), min(a[1] + a[3], b[1] + b[3])
    inter = max(0.0, x1 - x0) * max(0.0, y1 - y0)
    union = a[2] * a[3] + b[2] * b[3] - inter
    return inter / union if union > 0 else 0.0


def box_motion(old: Box, new: Box) -> FloatArray:
    """The similarity (scale about the centre + shift) taking box ``old`` to box ``new``."""
    s = float(np.sqrt((new[2] * new[3]) / max(old[2] * old[3], 1e-9)))
    ocx, ocy = old[0] + old[2] / 2, old[1] + old[3] / 2
    ncx, ncy = new[0] + new[2] / 2, new[1] + new[3] / 2
    return np.array([[s, 0.0, ncx - s * ocx], [0.0, s, ncy - s * ocy], [0.0, 0.0, 1.0]])


def clip_box(box: Box, width: int, height: int) -> Box | None:
    """``box`` cut to the image; None when too little is left to track."""
    x0, y0 = max(0.0, box[0]), max(0.0, box[1])
    x1, y1 = min(float(width), box[0] + box[2]), min(float(height), box[1] + box[3])
    if x1 - x0 < 4 or y1 - y0 < 4:
        return None
    return (x0, y0, x1 - x0, y1 - y0)


class Perception:
    """The pipeline's :class:`~companion.app.FrameProcessor`."""

    def __init__(self, camera: CameraModel, landmarks: Sequence[MapLandmark],
                 references: Mapping[str, npt.NDArray[np.uint8]],
                 sensors: Callable[[], SideSensors] = SideSensors,
                 config: PerceptionConfig | None = None,
                 tracker_config: TrackerConfig | None = None,
                 pose_config: PoseConfig | None = None,
                 acquire_config: AcquireConfig | None = None, seed: int = 0) -> None:
        self.camera = camera
        self.landmarks = list(landmarks)
        self.config = config or PerceptionConfig()
        self.tracker_config = tracker_config
        self.pose_config = pose_config or PoseConfig()
        self.sensors = sensors
        self.matcher = ReferenceMatcher(acquire_config)
        self.unmatchable: dict[str, str] = {}
        for lid, image in references.items():
            try:
                self.matcher.add(lid, image)
            except ValueError as err:
                self.unmatchable[lid] = str(err)
        self.tracks: dict[str, Track] = {}
        self._seed = seed
        self._frames = 0

    def process(self, frame: Frame) -> FrameResult:
        """Track, acquire, solve: one frame in, tracks and maybe a fix out."""
        image = frame.image
        events: list[dict[str, Any]] = []
        if image.shape[:2] != (self.camera.height, self.camera.width):
            return FrameResult(frame.index, frame.t_us, bad_frame=True,
                               no_fix_reason=f"frame {image.shape[1]}x{image.shape[0]} is "
                               f"not the camera's {self.camera.width}x{self.camera.height}")
        gray = np.asarray(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), np.uint8)
        for lid in list(self.tracks):
            if not self._update_track(self.tracks[lid], image, gray):
                del self.tracks[lid]
                events.append({"event": "lost", "landmark": lid})
        if self._should_acquire():
            events += self._acquire(image)
        self._frames += 1
        return self._solve(frame, events)

    # -- tracking ---------------------------------------------------------------------

    def _update_track(self, track: Track, image: npt.NDArray[np.uint8],
                      gray: npt.NDArray[np.uint8]) -> bool:
        result: TrackResult = track.tracker.update(image)
        if result.box is None or result.confidence < self.config.min_track_confidence:
            return False
        old_box, track.box = track.box, result.box
        track.confidence, track.features = result.confidence, result.features
        track.corners = None
        if self.config.refine_corners and track.homography is not None:
            predicted = box_motion(old_box, track.box) @ track.homography
            track.homography = self._refine(track.landmark_id, gray, predicted, track.box)
            if track.homography is not None:
                track.corners = self._corners(track.landmark_id, track.homography)
        return True

    def _refine(self, lid: str, gray: npt.NDArray[np.uint8], hom: FloatArray,
                box: Box) -> FloatArray | None:
        ref = self.matcher.references[lid]
        refined = refine_ecc(ref, gray, hom, self.config.ecc_iterations)
        corners = self._corners(lid, refined)
        x0, y0 = corners.min(axis=0)
        x1, y1 = corners.max(axis=0)
        if box_iou((x0, y0, x1 - x0, y1 - y0), box) < self.config.min_corner_agreement:
            return None  # the alignment wandered off: keep the box, drop the corners
        return refined

    def _corners(self, lid: str, hom: FloatArray) -> FloatArray:
        w, h = self.matcher.references[lid].size_px
        quad = np.array([[0, 0], [w, 0], [w, h], [0, h]], np.float64).reshape(-1, 1, 2)
        return np.asarray(cv2.perspectiveTransform(quad, hom).reshape(4, 2), np.float64)

    # -- acquisition ------------------------------------------------------------------

    def _should_acquire(self) -> bool:
        if len(self.tracks) >= self.config.max_tracks:
            return False
        return not self.tracks or self._frames % self.config.acquire_every_frames == 0

    def _acquire(self, image: npt.NDArray[np.uint8]) -> list[dict[str, Any]]:
        wanted = [lid for lid in self.matcher.references if lid not in self.tracks]
        events: list[dict[str, Any]] = []
        height, width = image.shape[:2]
        for match in self.matcher.find(image, wanted):
            box = clip_box(match.box, width, height)
            if box is None or len(self.tracks) >= self.config.max_tracks:
                continue
            tracker = AdaptiveTracker(self.tracker_config, seed=self._seed + len(self.tracks))
            tracker.init(image, box)
            self.tracks[match.landmark_id] = Track(match.landmark_id, tracker, box,
                                                   match.homography, corners=match.corners_px)
            events.append({"event": "acquired", "landmark": match.landmark_id,
                           "box": [round(v, 1) for v in box], "inliers": match.inliers})
        return events

    # -- pose -------------------------------------------------------------------------

    def observations(self, frame_index: int) -> list[Observation]:
        """One observation per live track (corners when the alignment holds)."""
        out = []
        for t in self.tracks.values():
            x, y, w, h = t.box
            corners = None if t.corners is None else tuple(
                (float(u), float(v)) for u, v in t.corners)
            centre = ((x + w / 2, y + h / 2) if t.corners is None
                      else tuple(float(c) for c in t.corners.mean(axis=0)))
            out.append(Observation(centre_px=(float(centre[0]), float(centre[1])),
                                   box_wh_px=(w, h), confidence=t.confidence,
                                   landmark_id=t.landmark_id, corners_px=corners,
                                   frame_index=frame_index))
        return out

    def _solve(self, frame: Frame, events: list[dict[str, Any]]) -> FrameResult:
        tracks = tuple(
            {"landmark_id": t.landmark_id, "box": [round(v, 1) for v in t.box],
             "confidence": round(t.confidence, 3), "features": list(t.features),
             "corners": None if t.corners is None else np.round(t.corners, 2).tolist()}
            for t in self.tracks.values()
        )
        if not self.tracks:
            return FrameResult(frame.index, frame.t_us, tracks, None, "nothing tracked",
                               tuple(events))
        side = self.sensors()
        fix = solve_pose(self.observations(frame.index), self.landmarks, self.camera,
                         frame.t_us, attitude=side.attitude, altitude=side.altitude,
                         laser=side.laser, config=self.pose_config)
        if isinstance(fix, NoFix):
            return FrameResult(frame.index, frame.t_us, tracks, None, fix.reason, tuple(events))
        return FrameResult(frame.index, frame.t_us, tracks, fix, None, tuple(events),
                           pose_json=pose_json(fix))


def pose_json(fix: PoseFix) -> dict[str, Any]:
    """The monitoring payload of a fix (docs/monitoring.md)."""
    return {
        "position_ned_m": [round(v, 4) for v in fix.position_ned_m],
        "attitude_rpy_rad": [round(v, 5) for v in fix.attitude_rpy_rad],
        "covariance_diag": [float(f"{v:.6g}") for v in np.diag(fix.covariance)],
        "quality": fix.quality,
        "landmark_ids": list(fix.landmark_ids),
        "solver": fix.solver,
    }
