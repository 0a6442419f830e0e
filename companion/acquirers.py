"""The four ways to find a map landmark that is not tracked, one class each behind one
small protocol (:class:`Acquirer`), all ending in :meth:`Starter.start` (the warped
appearance must match before a track starts, so a wall is never taken for a sign):

* :class:`FeatureAcquirer`: feature matching against the appearance references;
* :class:`PredictionAcquirer`: the frame's fix says where an untracked landmark is,
  alignment (ECC) confirms it;
* :class:`DetectorAcquirer`: the landmark detector's hits, each confirmed by alignment;
* :class:`SearchAcquirer`: a colour template search over the frame, one landmark a call.

They run on the pipeline's background lane (:class:`companion.acquisition.Acquisition`
decides which, when) and never see the live tracks: a :class:`Sighting` carries the
frame and a snapshot of which landmarks are taken (:class:`~companion.perception_types.
Occupancy`); what they start is handed to the worker thread under the track set's lock
(:meth:`companion.tracks.TrackSet.hand_over`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from companion.corners import box_partial, ecc
from companion.perception_types import (
    DetectFn,
    Occupancy,
    PerceptionConfig,
    Start,
    Track,
    feature_weights_bgr,
)
from companion.side_sensors import PoseGuess
from tracker import AdaptiveTracker, TrackerConfig
from tracker.acquire import (
    Reference,
    ReferenceMatcher,
    homography_to,
    project_corners,
    search_template,
)
from tracker.boxes import box_corners, clip_box, in_view_share, inside, outline_box, squashed
from tracker.camera import CameraModel
from tracker.edge_align import align_cut, search_shift, shifted
from tracker.pose.landmarks import landmark_corners_ned
from tracker.pose.types import ONE_BEARING_SOLVERS, MapLandmark, PoseFix
from tracker.types import Box
from tracker.verify import detail_ncc, part_nccs

FloatArray = npt.NDArray[np.float64]
Image = npt.NDArray[np.uint8]

#: Trackers started n-th re-rank their features n x this many frames apart (a re-rank costs
#: a few ms: several on one frame showed in the latency's tail).
RANK_PHASE_STEP = 3
#: The acquirers that name a plate by its appearance alone (not by where the map puts it):
#: a look-alike can be named instead, so every quarter of the plate must match
#: (``min_part_ncc``).  A plate placed by the fix or the autopilot's estimate is named by
#: its place; there a plain sign's quarter, mostly its border, follows what is behind it
#: (the street's bus stop: 0.0-0.3 against a dark window, 0.8 against the wall).
BY_APPEARANCE = frozenset({"features", "detector", "search"})
#: A predicted outline this far inside the image is a whole plate (aligned by ECC).
WHOLE_MARGIN_PX = 4.0


@dataclass(frozen=True)
class Sighting:
    """One frame as acquisition sees it: the image (rectified), which landmarks are taken
    when housekeeping began, the frame's fix (None: no fix), and without a fix the
    autopilot's own pose estimate (None: none, or a fix)."""

    image: Image
    seen: Occupancy
    fix: PoseFix | None = None
    guess: PoseGuess | None = None

    @property
    def cut_wanted(self) -> bool:
        """Plates cut by the image's edge are looked for: without a fix, or beside a fix
        from one landmark's bearing (:data:`~tracker.pose.types.ONE_BEARING_SOLVERS`).
        Their corners are the weakest, worth it only where little else is in view; a hover
        where one cut plate's corner gave the fixes (the strict square's (6, 6): sd 1.3-3 m)
        took the autopilot 0.5-0.6 m off (docs/decisions.md, "A cut plate is looked for
        beside a one-bearing fix")."""
        return self.fix is None or self.fix.solver in ONE_BEARING_SOLVERS


class Acquirer(Protocol):
    """One way to find untracked landmarks in a frame; ``earlier``: what this
    housekeeping call started before (taken, and counted in the seeds)."""

    def find(self, sight: Sighting, earlier: Sequence[Start] = ()) -> list[Start]: ...


class Starter:
    """Starts a verified track: the landmark's appearance warped by the homography found
    must match the frame's (``min_appearance_ncc``), found by appearance alone on every
    quarter of the plate with detail (``min_part_ncc``, :data:`BY_APPEARANCE`), at a place
    no other track holds (:meth:`Occupancy.crowded`)."""

    def __init__(self, references: Mapping[str, Reference], config: PerceptionConfig,
                 tracker_config: TrackerConfig | None, seed: int) -> None:
        self.references = references
        self.config = config
        self.tracker_config = tracker_config
        self.seed = seed

    def start(self, lid: str, sight: Sighting, box: Box, hom: FloatArray, corners: FloatArray,
              by: str, starts: Sequence[Start]) -> list[Start]:
        """A tracker for landmark ``lid`` in ``box`` with a homography, verified first by
        the appearance it warps onto the frame (none when that does not match); its seed
        and re-rank phase follow how many tracks are busy (``starts``: this call's)."""
        image = sight.image
        ref = self.references[lid]
        if squashed(corners, ref.size_px):
            return []  # a sliver is no plate in view (tracker.boxes.MIN_FORESHORTENING)
        if sight.seen.crowded(box, starts):
            return []  # matchers run best first: the place went to the better match
        least = self.config.min_part_ncc if by in BY_APPEARANCE else 0.0
        ncc, parts = part_nccs(ref, image, hom) if least > 0 else (detail_ncc(ref, image, hom), [])
        if ncc < self.config.min_appearance_ncc or min(parts, default=1.0) < least:
            return []
        busy = sight.seen.busy(starts)
        tracker = AdaptiveTracker(self.tracker_config, seed=self.seed + busy)
        tracker.init(image, box, rank_phase=RANK_PHASE_STEP * busy)
        track = Track(lid, tracker, box, hom, corners=corners,
                      align_weights=feature_weights_bgr(tracker.features),
                      partial_box=box_partial(corners, image.shape[1], image.shape[0]))
        return [Start(track, {"event": "acquired", "landmark": lid, "by": by,
                              "box": [round(v, 1) for v in box],
                              "appearance_correlation": round(ncc, 3)})]

    def start_aligned(self, lid: str, sight: Sighting, aligned: FloatArray, by: str,
                      starts: Sequence[Start]) -> list[Start]:
        """:meth:`start` on the box of the outline ``aligned`` projects (none when that
        box is not in the image)."""
        image = sight.image
        quad = project_corners(self.references[lid], aligned)
        box = clip_box(outline_box(quad), image.shape[1], image.shape[0])
        if box is None:
            return []
        return self.start(lid, sight, box, aligned, quad, by, starts)


class FeatureAcquirer:
    """Feature matching against the appearance references (ORB/SIFT + verified
    homography)."""

    def __init__(self, matcher: ReferenceMatcher, starter: Starter) -> None:
        self.matcher = matcher
        self.starter = starter

    def find(self, sight: Sighting, earlier: Sequence[Start] = ()) -> list[Start]:
        wanted = [lid for lid, ref in self.matcher.references.items()
                  if ref.matchable and not sight.seen.taken(lid, earlier)]
        starts: list[Start] = list(earlier)
        height, width = sight.image.shape[:2]
        for match in self.matcher.find(sight.image, wanted, cut=sight.cut_wanted):
            box = clip_box(match.box, width, height)
            if box is None or sight.seen.busy(starts) >= self.starter.config.max_tracks:
                continue
            starts += self.starter.start(match.landmark_id, sight, box, match.homography,
                                         match.corners_px, "features", starts)
        return starts[len(earlier):]


class PredictionAcquirer:
    """Map landmarks the fix says are in view, confirmed by alignment: finds plain plates
    with too few keypoints for feature matching, and plates cut by the image's edge (their
    part in view aligned: :func:`tracker.edge_align.align_cut`; without a fix or beside a
    one-bearing fix: :attr:`Sighting.cut_wanted`).  Needs
    the sighting's fix, or without one the autopilot's pose estimate (``by`` "estimate":
    its error bound ``max_guess_error_px``; what it finds is verified like any sighting)."""

    def __init__(self, camera: CameraModel, landmarks: Sequence[MapLandmark],
                 starter: Starter) -> None:
        self.camera = camera
        self.landmarks = list(landmarks)
        self.starter = starter

    def find(self, sight: Sighting, earlier: Sequence[Start] = ()) -> list[Start]:
        """The fix predicts where each untracked landmark's corners are; aligning its
        reference there (ECC) confirms it and gives exact corners."""
        pose: PoseFix | PoseGuess | None = sight.fix if sight.fix is not None else sight.guess
        if pose is None:
            return []
        cfg, refs = self.starter.config, self.starter.references
        by = "prediction" if sight.fix is not None else "estimate"
        height, width = sight.image.shape[:2]
        starts: list[Start] = list(earlier)
        for lm in self.landmarks:
            lid = lm.landmark_id
            if sight.seen.taken(lid, starts) or lid not in refs:
                continue
            if sight.seen.busy(starts) >= cfg.max_tracks:
                break
            corners = self.project(lm, pose)
            ref = refs[lid]
            aligned = None if corners is None else self.align(
                ref, sight.image, corners, cut=sight.cut_wanted)
            if corners is None or aligned is None:
                continue
            # a whole plate predicted by a fix: within max_prediction_error_px; from the
            # autopilot's estimate, or cut beside a one-bearing fix (whose error along
            # its weak axis is the estimate's size): within max_guess_error_px
            whole = inside(corners, width, height, margin=WHOLE_MARGIN_PX)
            bound = cfg.max_prediction_error_px if sight.fix is not None and whole \
                else cfg.max_guess_error_px
            quad = project_corners(ref, aligned)
            if np.abs(quad - corners).max() > bound:
                continue
            starts += self.starter.start_aligned(lid, sight, aligned, by, starts)
        return starts[len(earlier):]

    def align(self, ref: Reference, image: Image, corners: FloatArray, cut: bool
              ) -> FloatArray | None:
        """The homography that aligns ``ref`` where the pose predicts its ``corners``: the
        whole plate (ECC, held to ``verify_correlation``), or with ``cut`` a plate cut by
        the image's edge with ``predict_cut_in_view`` of it in view by its part in view;
        None when neither holds.  Cut plates only without a fix or beside a one-bearing
        one (:attr:`Sighting.cut_wanted`): their corners are the weakest and add little to
        a fix that comes anyway (real-imagery world seed 2, replayed: RMSE 1.00 -> 1.11 % of
        distance with them), but with nothing else in view they bring the fixes back
        (docs/decisions.md)."""
        cfg = self.starter.config
        height, width = image.shape[:2]
        predicted = homography_to(ref, corners)
        if inside(corners, width, height, margin=WHOLE_MARGIN_PX):
            return ecc(cfg, ref, image, predicted)
        if not cut or in_view_share(corners, width, height) < cfg.predict_cut_in_view:
            return None
        starts = [predicted]
        moved = search_shift(ref, image, predicted, cfg.max_guess_error_px,
                             cfg.verify_correlation)
        if moved is not None and moved != (0.0, 0.0):
            starts.insert(0, shifted(predicted, *moved))
        for hom in starts:
            aligned = align_cut(ref, image, hom, cfg.ecc_iterations, cfg.verify_correlation)
            if aligned is not None:
                return aligned
        return None

    def project(self, lm: MapLandmark, fix: PoseFix | PoseGuess) -> FloatArray | None:
        """The landmark's corners in the image for the vehicle pose of ``fix``."""
        corners_ned = landmark_corners_ned(lm)
        cam = self.camera.world_to_camera(corners_ned, np.asarray(fix.position_ned_m),
                                          fix.attitude_rpy_rad)
        if np.any(cam[:, 2] <= 0.1):
            return None
        return self.camera.project_camera_points(cam)


class DetectorAcquirer:
    """The detector's hits: each is tried against the untracked map landmarks of its
    category, and kept only when the reference aligns there."""

    def __init__(self, detect: DetectFn, landmarks: Sequence[MapLandmark],
                 starter: Starter) -> None:
        self.detect = detect
        self.category = {lm.landmark_id: lm.category for lm in landmarks}
        self.starter = starter

    def find(self, sight: Sighting, earlier: Sequence[Start] = ()) -> list[Start]:
        cfg, refs = self.starter.config, self.starter.references
        image = sight.image
        height, width = image.shape[:2]
        starts: list[Start] = list(earlier)
        for det in self.detect(image):
            for lid, ref in refs.items():
                if sight.seen.taken(lid, starts) or \
                        self.category.get(lid) not in (det.category, ""):
                    continue
                aligned = ecc(cfg, ref, image, homography_to(ref, box_corners(det.box)))
                if aligned is None:
                    continue
                quad = project_corners(ref, aligned)
                box = clip_box(det.box, width, height)
                if box is not None and inside(quad, width, height, 2.0):
                    started = self.starter.start(lid, sight, box, aligned, quad, "detector",
                                                 starts)
                    starts += started
                    if started:
                        break
        return starts[len(earlier):]


class SearchAcquirer:
    """One untracked landmark a call (round robin) by colour template search over the
    whole frame, confirmed by alignment: finds distant or plain landmarks that feature
    matching misses, while nothing gives a fix to predict from."""

    def __init__(self, starter: Starter) -> None:
        self.starter = starter
        self._turn = 0

    def find(self, sight: Sighting, earlier: Sequence[Start] = ()) -> list[Start]:
        cfg, refs = self.starter.config, self.starter.references
        image = sight.image
        untracked = [lid for lid in refs if not sight.seen.taken(lid, earlier)]
        if not untracked or sight.seen.busy(earlier) >= cfg.max_tracks:
            return []
        lid = untracked[self._turn % len(untracked)]
        self._turn += 1
        ref = refs[lid]
        found = search_template(ref, image, cfg.search_widths_px)
        if found is None or found[0] < cfg.search_min_score:
            return []
        aligned = ecc(cfg, ref, image, found[1])
        if aligned is None:
            return []
        quad = project_corners(ref, aligned)
        if not inside(quad, image.shape[1], image.shape[0], margin=2.0):
            return []
        return self.starter.start_aligned(lid, sight, aligned, "search", earlier)
