"""Perception's acquisition: finding map landmarks that are not tracked, and starting a
verified track on each (:class:`Acquisition`, a part of :class:`companion.perception.Perception`).

Four strategies, each ending in :meth:`Acquisition._start` (the warped appearance must match
before a track starts, so a wall is never taken for a sign):

* feature matching against the appearance references (``_acquire``), now and then and at
  once whenever nothing is tracked;
* prediction from the frame's fix (``_predict_acquire``): the fix says where an untracked
  landmark is, alignment (ECC) confirms it;
* the detector's hits (``_detect_acquire``) and a colour template search over the frame
  (``_search``) while no fix comes (``_find_while_lost``; with tracks running they take
  turns, one heavy step per housekeeping call: docs/benchmarks.md, "Latency tail").

These run on the pipeline's housekeeping thread; what they start is handed to ``process``
under the perception's lock (``_pending``).
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from companion.app import Frame
from companion.perception_types import (
    TRACK_MIN_CORRELATION,
    DetectFn,
    PerceptionConfig,
    Start,
    Track,
    feature_weights_bgr,
)
from tracker import AdaptiveTracker, TrackerConfig
from tracker.acquire import (
    Reference,
    ReferenceMatcher,
    Weights,
    homography_to,
    project_corners,
    refine_ecc,
    search_template,
)
from tracker.boxes import box_corners, clip_box, inside
from tracker.camera import CameraModel
from tracker.pose.landmarks import landmark_corners_ned
from tracker.pose.types import MapLandmark, PoseFix
from tracker.types import Box
from tracker.verify import detail_ncc

FloatArray = npt.NDArray[np.float64]

#: Trackers started n-th re-rank their features n x this many frames apart (a re-rank costs
#: a few ms: several on one frame showed in the latency's tail).
RANK_PHASE_STEP = 3


class Acquisition:
    """The acquisition half of :class:`~companion.perception.Perception` (which sets these
    attributes in its ``__init__``)."""

    camera: CameraModel
    landmarks: list[MapLandmark]
    config: PerceptionConfig
    tracker_config: TrackerConfig | None
    matcher: ReferenceMatcher
    detect: DetectFn | None
    tracks: dict[str, Track]
    _lock: threading.Lock
    _pending: list[Start]
    _seed: int
    _last_fix_us: int
    _acquired_frame: int
    _search_turn: int
    _search_next: bool

    def _find_while_lost(self, image: npt.NDArray[np.uint8], spread: bool) -> list[Start]:
        """Without a fix: the detector's hits, and the template search when they start
        nothing -- with ``spread``, on the next call (each costs 20-45 ms of CPU)."""
        if self.detect is not None and not self._search_next:
            found = self._detect_acquire(image)
            if found or not spread:
                return found or self._search(image)
            self._search_next = True
            return found
        self._search_next = False
        return self._search(image)

    def _ecc(self, ref: Reference, frame: npt.NDArray[np.uint8], hom: FloatArray,
             verify: bool = True, weights: Weights | None = None) -> FloatArray | None:
        """ECC alignment with this perception's settings; ``verify``: a new sighting,
        held to ``verify_correlation`` (a running track to ``TRACK_MIN_CORRELATION``)."""
        cfg = self.config
        least = cfg.verify_correlation if verify else TRACK_MIN_CORRELATION
        return refine_ecc(ref, frame, hom, cfg.ecc_iterations, least, cfg.ecc_fine_iterations,
                          weights)

    def _busy(self, starts: Sequence[Start] = ()) -> int:
        """Tracks running, waiting to be adopted and just started."""
        with self._lock:
            waiting = len(self._pending)
        return len(self.tracks) + waiting + len(starts)

    def _taken(self, lid: str, starts: Sequence[Start] = ()) -> bool:
        """Tracked, waiting to be adopted, or just started."""
        with self._lock:
            waiting = [s.track.landmark_id for s in self._pending]
        return lid in self.tracks or lid in waiting or any(
            s.track.landmark_id == lid for s in starts)

    def _should_acquire(self, frame: Frame) -> bool:
        """Feature matching is due: nothing tracked, or ``acquire_every_frames`` since the
        last (``acquire_every_frames_with_fix`` while fixes come: prediction then finds the
        plates in view, at a fraction of SIFT's cost)."""
        cfg = self.config
        if self._busy() >= cfg.max_tracks:
            return False
        recent_fix = frame.t_us - self._last_fix_us <= cfg.search_after_s * 1e6
        every = cfg.acquire_every_frames_with_fix if recent_fix else cfg.acquire_every_frames
        return not self.tracks or frame.index - self._acquired_frame >= every

    def _acquire(self, image: npt.NDArray[np.uint8]) -> list[Start]:
        wanted = [lid for lid, ref in self.matcher.references.items()
                  if ref.matchable and not self._taken(lid)]
        starts: list[Start] = []
        height, width = image.shape[:2]
        for match in self.matcher.find(image, wanted):
            box = clip_box(match.box, width, height)
            if box is None or self._busy(starts) >= self.config.max_tracks:
                continue
            starts += self._start(match.landmark_id, image, box, match.homography,
                                  match.corners_px, "features", starts)
        return starts

    def _start(self, lid: str, image: npt.NDArray[np.uint8], box: Box, hom: FloatArray,
               corners: FloatArray, by: str, starts: Sequence[Start]) -> list[Start]:
        """A tracker for landmark ``lid`` in ``box`` with a homography, verified first by
        the appearance it warps onto the frame (none when that does not match)."""
        ncc = detail_ncc(self.matcher.references[lid], image, hom)
        if ncc < self.config.min_appearance_ncc:
            return []
        busy = self._busy(starts)
        tracker = AdaptiveTracker(self.tracker_config, seed=self._seed + busy)
        tracker.init(image, box, rank_phase=RANK_PHASE_STEP * busy)
        track = Track(lid, tracker, box, hom, corners=corners,
                      align_weights=feature_weights_bgr(tracker.features))
        return [Start(track, {"event": "acquired", "landmark": lid, "by": by,
                              "box": [round(v, 1) for v in box],
                              "appearance_correlation": round(ncc, 3)})]

    def _detect_acquire(self, image: npt.NDArray[np.uint8]) -> list[Start]:
        """Restart tracks from detector hits: each hit is tried against the untracked map
        landmarks of its category, and kept only when the reference aligns there."""
        assert self.detect is not None
        starts: list[Start] = []
        category = {lm.landmark_id: lm.category for lm in self.landmarks}
        for det in self.detect(image):
            for lid, ref in self.matcher.references.items():
                if self._taken(lid, starts) or category.get(lid) not in (det.category, ""):
                    continue
                start = homography_to(ref, box_corners(det.box))
                aligned = self._ecc(ref, image, start)
                if aligned is None:
                    continue
                quad = project_corners(ref, aligned)
                box = clip_box(det.box, image.shape[1], image.shape[0])
                if box is not None and inside(quad, image.shape[1], image.shape[0], 2.0):
                    started = self._start(lid, image, box, aligned, quad, "detector", starts)
                    starts += started
                    if started:
                        break
        return starts

    def _search(self, image: npt.NDArray[np.uint8]) -> list[Start]:
        """Look for one untracked landmark (round robin) by colour template search over the
        whole frame, verified by alignment: finds distant or plain landmarks that feature
        matching misses, while nothing gives a fix to predict from."""
        untracked = [lid for lid in self.matcher.references if not self._taken(lid)]
        if not untracked or self._busy() >= self.config.max_tracks:
            return []
        lid = untracked[self._search_turn % len(untracked)]
        self._search_turn += 1
        ref = self.matcher.references[lid]
        found = search_template(ref, image, self.config.search_widths_px)
        if found is None or found[0] < self.config.search_min_score:
            return []
        aligned = self._ecc(ref, image, found[1])
        if aligned is None:
            return []
        quad = project_corners(ref, aligned)
        x0, y0 = quad.min(axis=0)
        x1, y1 = quad.max(axis=0)
        box = clip_box((x0, y0, x1 - x0, y1 - y0), image.shape[1], image.shape[0])
        if box is None or not inside(quad, image.shape[1], image.shape[0], margin=2.0):
            return []
        return self._start(lid, image, box, aligned, quad, "search", [])

    def _predict_acquire(self, image: npt.NDArray[np.uint8], fix: PoseFix,
                         earlier: Sequence[Start]) -> list[Start]:
        """Start tracks on map landmarks the fix says are in view, verified by alignment.

        The fix predicts where each untracked landmark's corners are; aligning its
        reference there (ECC) confirms it and gives exact corners.  This finds plain
        plates that have too few keypoints for feature matching.
        """
        starts: list[Start] = list(earlier)
        height, width = image.shape[:2]
        for lm in self.landmarks:
            lid = lm.landmark_id
            if self._taken(lid, starts) or lid not in self.matcher.references:
                continue
            if self._busy(starts) >= self.config.max_tracks:
                break
            corners = self._project(lm, fix)
            if corners is None or not inside(corners, width, height, margin=4.0):
                continue
            ref = self.matcher.references[lid]
            aligned = self._ecc(ref, image, homography_to(ref, corners))
            if aligned is None:
                continue
            quad = project_corners(ref, aligned)
            if np.abs(quad - corners).max() > self.config.max_prediction_error_px:
                continue
            x0, y0 = quad.min(axis=0)
            x1, y1 = quad.max(axis=0)
            box = clip_box((x0, y0, x1 - x0, y1 - y0), width, height)
            if box is None:
                continue
            starts += self._start(lid, image, box, aligned, quad, "prediction", starts)
        return starts[len(earlier):]

    def _project(self, lm: MapLandmark, fix: PoseFix) -> FloatArray | None:
        """The landmark's corners in the image for the vehicle pose of ``fix``."""
        corners_ned = landmark_corners_ned(lm)
        cam = self.camera.world_to_camera(corners_ned, np.asarray(fix.position_ned_m),
                                          fix.attitude_rpy_rad)
        if np.any(cam[:, 2] <= 0.1):
            return None
        return self.camera.project_camera_points(cam)
