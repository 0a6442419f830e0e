"""A running track's corners: where exactly its landmark's outline is in this frame.

The tracker says *where* (a box); :class:`Corners` says *exactly where the corners are*, by
aligning the landmark's appearance reference onto the frame (ECC), started from the last
homography: a whole plate by :meth:`Corners.align`, a plate cut by the image's edge by the
affine alignment of its part in view (:meth:`Corners.align_cut`), and, when the alignment
is lost, by :meth:`Corners.recover` (the reference aligned on the box, else its features
re-matched around it).  :meth:`Corners.check` is the periodic appearance check.

Each call touches only the track it is given; the track set calls these for different
tracks on two threads at once (:class:`companion.tracks.TrackSet`).  The one object they
share, the feature matcher of :meth:`Corners.recover`, is behind its own lock; the
references are read-only.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping

import cv2
import numpy as np
import numpy.typing as npt

from companion.perception_types import TRACK_MIN_CORRELATION, PerceptionConfig, Track
from tracker.acquire import (
    Reference,
    ReferenceMatcher,
    Weights,
    homography_to,
    project_corners,
    reference_plane,
    refine_ecc,
)
from tracker.boxes import (
    box_corners,
    box_iou,
    centre_on,
    clip_box,
    in_view_share,
    inside,
    outline_box,
    saturated_share,
    squashed,
)
from tracker.camera import CameraModel
from tracker.edge_align import align_cut, box_shift, patch_around, patch_shift, shifted
from tracker.types import Box
from tracker.verify import check_appearance, check_appearance_near, quad_iou

FloatArray = npt.NDArray[np.float64]

#: A colour feature is aligned on only when the reference shows at least this share of its
#: grey levels' contrast (standard deviation, taken as at least 1) in it: the tracker
#: picks its feature on the frame, where a grey reference photo's plate may carry a colour
#: cast the photo has not (issue 25's warm light: the reference's R - B plane was 0
#: everywhere and every alignment on it failed, "NaN encountered").
MIN_PLANE_CONTRAST = 0.1

#: A tracker's box seated on a plate with less than this share of it in view holds the part
#: in view, its centre off the plate's by a twentieth of the plate or more; it is re-seated
#: on the plate once the plate is whole in the image (:meth:`Corners.follow`).
PARTIAL_BOX_SHARE = 0.9


#: A plate whose outline has less than this share of it in the image has left the view: its
#: tracker's box holds the part that was last in view, on the background (a plate leaving at
#: the bottom edge of the real-imagery world seed 1: its box stayed 98 px tall while 10 to
#: 1 px of the plate were in view, then followed nothing for 3 frames).
LEFT_VIEW_SHARE = 0.1

#: A cut plate's tracker box whose part in the image overlaps the part of the outline in view
#: less than this (IoU), and is the larger, was left on the background by a plate leaving the
#: image: the particles cannot follow a plate across the image's edge, so the tracker is
#: seated on the part in view again (the real-imagery world seed 57's real-02: its box 76 x
#: 140 px over the 16 to 5 rows of the plate in view for 14 frames, scored on a wrong place).
#: Only on a held outline (``Track.outline_held``): real seed 44's real-02 jumped 25-60 px as
#: it left, and a box seated there sat on a wrong place for 6 frames.  The track goes on
#: while its corners hold (``LEFT_VIEW_SHARE``): ending it on the box lost corners that fixes
#: still needed (real seed 73).  A plate entering keeps the box seated on its first part
#: until it is whole (:meth:`Corners._seat`): seating it on each larger part moved real seed
#: 43's RMSE over issue 25's target (docs/decisions.md, "A leaving plate's box seated on its
#: part in view").
PART_IOU = 0.5


#: Largest change of a cut plate's outline size (the square root of its area) from one frame
#: to the next that keeps its part out of view held (``Track.outline_held``): wall-02 leaving
#: the flown square's view changed 1-2 % a frame; the survey's wall-04, 25 % when its
#: alignment jumped (its corners out of view 15-20 px off).
HELD_SIZE_STEP = 0.1

#: A cut plate's alignment that grows its outline (the square root of its area) by more than
#: this share, shrinks it to under 1 / (1 + this), or turns it in the image by more than
#: ``MAX_CUT_TURN_DEG``, from one processed frame to the next, gives no corners (its
#: homography is kept and tried again next frame): no flight moves a plate so far in a
#: frame.  The strict square beside a busy core (seed 1, 23.07 s): sign-01, cut by the
#: bottom edge, 283 x 135 px, was aligned the next frame onto an outline 3.5 times its size
#: and turned 62 deg; the ECC windows over that outline took 0.25-0.4 s a frame, the fixes
#: were refused as stale and both tracks were lost (2.56 s without a fix; docs/decisions.md,
#: "A cut plate's outline may not jump").  The survey's wall-04 shrank 25 % in a frame when
#: its alignment slipped (``HELD_SIZE_STEP``: kept, its part out of view no longer held).
MAX_CUT_SIZE_STEP = 0.4
MAX_CUT_TURN_DEG = 30.0


def outline_angle(corners: FloatArray) -> float:
    """The direction (deg, image axes) of an outline's left-to-right axis: from the middle
    of its left side (corners 0 and 3) to the middle of its right side (1 and 2)."""
    dx, dy = (corners[1] + corners[2] - corners[0] - corners[3]) / 2.0
    return math.degrees(math.atan2(float(dy), float(dx)))


def box_partial(corners: FloatArray, width: int, height: int) -> bool:
    """Does a tracker's box seated on the outline ``corners`` hold only part of its plate?"""
    return in_view_share(corners, width, height) < PARTIAL_BOX_SHARE


def grey_aligned(config: PerceptionConfig, ref: Reference) -> bool:
    """Does a running track of ``ref`` align its unsmoothed stage on grey levels alone?
    A plate with little colour (its luma's gradient energy at least
    ``ecc_grey_from_ratio`` times its chroma's: a photograph) does: in a frame its chroma
    is mostly the camera's chroma error, which the mixed plane scales up to unit spread."""
    least = config.ecc_grey_from_ratio
    return least > 0 and ref.luma_over_chroma >= least


def ecc(config: PerceptionConfig, ref: Reference, frame: npt.NDArray[np.uint8],
        hom: FloatArray, verify: bool = True, weights: Weights | None = None
        ) -> FloatArray | None:
    """ECC alignment with the perception's settings; ``verify``: a new sighting, held to
    ``verify_correlation`` over the whole reference (a running track to
    ``TRACK_MIN_CORRELATION``, its outer ring left out: ``ecc_edge_band_px``, and its
    unsmoothed stage on the feature mixed with grey levels: ``ecc_fine_grey_share``, or on
    grey levels alone: :func:`grey_aligned`)."""
    share = 1.0 if grey_aligned(config, ref) else config.ecc_fine_grey_share
    least, band, grey = ((config.verify_correlation, 0, 0.0) if verify
                         else (TRACK_MIN_CORRELATION, config.ecc_edge_band_px, share))
    return refine_ecc(ref, frame, hom, config.ecc_iterations, least,
                      config.ecc_fine_iterations, weights, band, grey,
                      config.ecc_band_from_px)


def moved_to_box(ref: Reference, hom: FloatArray, box: Box) -> FloatArray:
    """``hom`` moved so that the outline it projects is centred on the tracker's ``box``
    (a track without corners this frame: its last homography, where the tracker is)."""
    x, y, w, h = box
    dx, dy = np.array([x + w / 2, y + h / 2]) - project_corners(ref, hom).mean(axis=0)
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]]) @ hom


class Corners:
    """Corner alignment, recovery and the appearance check of the tracks of one camera."""

    def __init__(self, camera: CameraModel, config: PerceptionConfig,
                 references: Mapping[str, Reference], recover_matcher: ReferenceMatcher
                 ) -> None:
        self.camera = camera
        self.config = config
        self.references = references
        self._recover_matcher = recover_matcher
        self._recover_lock = threading.Lock()  # tracks may recover corners on two threads
        #: (landmark, weights) -> does the reference hold contrast in that feature?
        self._plane_ok: dict[tuple[str, Weights], bool] = {}

    def weights(self, track: Track) -> Weights | None:
        """The colour feature the track's corners are aligned on: its tracker's
        (``Track.align_weights``), or grey levels (None) when the reference is flat in it
        (``MIN_PLANE_CONTRAST``).  Two threads may both compute one entry: the same value."""
        w = track.align_weights
        if w is None:
            return None
        key = (track.landmark_id, w)
        ok = self._plane_ok.get(key)
        if ok is None:
            ref = self.references[track.landmark_id]
            grey = max(float(np.std(ref.gray)), 1.0)
            ok = float(np.std(reference_plane(ref, w))) >= MIN_PLANE_CONTRAST * grey
            self._plane_ok[key] = ok
        return w if ok else None

    def follow(self, track: Track, image: npt.NDArray[np.uint8], last_box: Box,
               motion: FloatArray | None = None) -> None:
        """The track's corners in ``image``, its tracker's box already updated (from
        ``last_box``): aligned from its last homography, recovered after misses.
        ``motion``: the image's move for the camera's turn since the last frame
        (:mod:`companion.ego_motion`); the alignment then starts from the last homography
        turned by it, and from the last one as it was if that fails."""
        track.corners, was, before = None, track.outline_held, track.homography
        if not self.config.refine_corners:
            return
        if track.homography is not None:
            predicted = track.homography  # landmarks move a few px a frame: ECC takes that up
            aligned = None if motion is None else self._align_turned(track, image, motion)
            if aligned is None:
                aligned = self.align_cut(track, image, predicted, last_box) if self.is_cut(
                    track.landmark_id, predicted) else self.align(track, image, predicted)
            ref = self.references[track.landmark_id]
            corners = None if aligned is None else project_corners(ref, aligned)
            if corners is not None and (squashed(corners, ref.size_px)
                                        or self._off_its_box(track, corners)
                                        or self._jumped(track.landmark_id, predicted,
                                                        aligned)):
                # a sliver (tracker.boxes.squashed): neither corners nor box.  Seen once in
                # ten real-time square flights: a plate entering at the image's edge aligned
                # onto a 7 px wide sliver, the tracker re-seated on it, and its box-only fix
                # 2.2 m off (docs/decisions.md, "A sliver is no plate"); or a cut outline
                # beside its tracker's box ("A cut outline must hold its tracker's box")
                aligned, corners = None, None
                track.disputed = True
            track.homography = predicted if aligned is None else aligned
            track.misses = 0 if aligned is not None else track.misses + 1
            track.corners = corners
        recovered = track.homography is None or track.misses >= self.config.max_corner_misses
        if recovered:
            self.recover(track, image)
        cut = track.homography is not None and self.is_cut(track.landmark_id, track.homography)
        # no corners: the homography kept is the one it had; found afresh: held if mostly
        # in view; aligned (whole or carried by the cut plate's alignment): held if mostly
        # in view, else if it was and its size did not jump
        track.outline_held = was if track.corners is None else not cut or (
            not recovered and was
            and self._same_size(track.landmark_id, before, track.homography))
        if track.corners is not None:
            track.disputed = False
            self._seat(track, image)
        track.patch = patch_around(image, track.corners) \
            if cut and track.corners is not None else None
        track.saturated = 0.0 if track.corners is None else \
            self._over_exposed(track.landmark_id, image, track.corners)

    def _over_exposed(self, landmark_id: str, image: npt.NDArray[np.uint8],
                      corners: FloatArray) -> float:
        """The share of the plate's pixels saturated beyond its own white
        (``Reference.white_share``): a white plate seen at 255 is not over-exposed, and
        its corners are no worse for it (docs/decisions.md, "A plate's own white is not
        over-exposure")."""
        white = self.references[landmark_id].white_share
        return max(0.0, saturated_share(image, corners) - white)

    def _size_ratio(self, landmark_id: str, before: FloatArray | None,
                    now: FloatArray | None) -> float | None:
        """The second homography's outline's size (the square root of its area) over the
        first's; None without both or with an empty first one."""
        if before is None or now is None:
            return None
        ref = self.references[landmark_id]
        a, b = (abs(float(cv2.contourArea(project_corners(ref, h).astype(np.float32))))
                for h in (before, now))
        return float(np.sqrt(b / a)) if a > 0.0 else None

    def _same_size(self, landmark_id: str, before: FloatArray | None,
                   now: FloatArray | None) -> bool:
        """Do the two homographies' outlines differ in size by at most
        ``HELD_SIZE_STEP``?  An alignment that moved a cut plate's outline by more jumped
        (a wrong start, a camera turn misread): its part out of view is no longer the shape
        it had."""
        ratio = self._size_ratio(landmark_id, before, now)
        return ratio is not None and abs(ratio - 1.0) <= HELD_SIZE_STEP

    def _jumped(self, landmark_id: str, before: FloatArray, now: FloatArray | None) -> bool:
        """Did a cut plate's alignment move its outline further than a flight can in a
        frame (``MAX_CUT_SIZE_STEP``, ``MAX_CUT_TURN_DEG``)?  False for a plate whole in
        both (held to its tracker's box already) and without an alignment."""
        if now is None or not (self.is_cut(landmark_id, before) or self.is_cut(landmark_id, now)):
            return False
        ratio = self._size_ratio(landmark_id, before, now)
        if ratio is None or not 1.0 / (1.0 + MAX_CUT_SIZE_STEP) <= ratio <= 1.0 + MAX_CUT_SIZE_STEP:
            return True
        ref = self.references[landmark_id]
        a, b = (outline_angle(project_corners(ref, h)) for h in (before, now))
        return abs(math.remainder(b - a, 360.0)) > MAX_CUT_TURN_DEG

    def _off_its_box(self, track: Track, corners: FloatArray) -> bool:
        """Does a cut plate's outline (one reaching out of the image) leave its tracker's
        box centre outside?  A whole plate's alignment is held to the box already
        (:meth:`_agrees`); a cut one's affine alignment on the part in view was not, and
        leaving (6, 6) on the strict square sign-01's ran 120-150 px beside its box for half
        a second, its fixes 1.1-1.8 m off (docs/decisions.md).  The box holds the part of
        the plate in view, so its centre lies on the plate when both are right."""
        return not inside(corners, self.camera.width, self.camera.height, margin=0.0) \
            and not centre_on(corners, track.box)

    def _seat(self, track: Track, image: npt.NDArray[np.uint8]) -> None:
        """A tracker whose box holds the part of a cut plate that was in view is started
        again on the plate's box once the plate is whole in the image (its features re-ranked
        there, its re-rank schedule kept); an outline cut now marks the box partial, and a
        partial box a leaving plate left on the background is seated on the part in view
        (:meth:`_hold_part`).  A box that kept the part's size while the plate came into
        view was centred ever further from it, until its outline was refused (the square's
        corners, frames perceived one in three: docs/decisions.md)."""
        assert track.corners is not None
        width, height = self.camera.width, self.camera.height
        if not inside(track.corners, width, height, margin=0.0):
            track.partial_box = track.partial_box or box_partial(track.corners, width, height)
            if track.partial_box:
                self._hold_part(track, image)
            return
        if not track.partial_box:
            return  # the usual case, every frame of every whole plate: nothing to do
        box = clip_box(outline_box(track.corners), width, height)
        if box is None:
            return
        track.tracker.init(image, box, rank_phase=track.tracker.state.since_rank)
        track.box, track.partial_box = box, False

    def _hold_part(self, track: Track, image: npt.NDArray[np.uint8]) -> None:
        """A cut plate's tracker started again on the part of its outline in view when its
        box's part in view overlaps that under ``PART_IOU`` and is the larger (left on the
        background by the plate leaving), and the outline is held (``Track.outline_held``:
        its size did not jump); its re-rank schedule kept."""
        assert track.corners is not None
        if not track.outline_held:
            return  # a cut outline that jumped (real seed 44's real-02, 25-60 px): not a guide
        part = clip_box(outline_box(track.corners), self.camera.width, self.camera.height)
        seen = clip_box(track.box, self.camera.width, self.camera.height)
        if part is None or seen is None or box_iou(part, seen) >= PART_IOU \
                or part[2] * part[3] >= seen[2] * seen[3]:
            return
        track.tracker.init(image, part, rank_phase=track.tracker.state.since_rank)
        track.box = part

    def coast(self, track: Track, image: npt.NDArray[np.uint8],
              motion: FloatArray | None = None) -> bool:
        """A whole plate's corners aligned from its last homography (turned by ``motion``)
        without the tracker, while its box agrees with that outline: kept when the outline
        found overlaps the one it started from by ``min_corner_agreement`` and is whole
        too.  False (the track as it was) otherwise: the tracker runs, then :meth:`follow`."""
        ref = self.references[track.landmark_id]
        if not self.config.refine_corners or track.homography is None \
                or track.corners is None \
                or not self._agrees(track.corners, track.corners, track.box):
            return False  # box-only, no outline, or the box is not on it: the tracker runs
        start = track.homography if motion is None else motion @ track.homography
        start = start / start[2, 2]
        if self.is_cut(track.landmark_id, start):
            return False
        aligned = ecc(self.config, ref, image, start, False, self.weights(track))
        track.tried = (start, aligned)
        if aligned is None or self.is_cut(track.landmark_id, aligned):
            return False
        corners = project_corners(ref, aligned)
        agreement = self.config.min_corner_agreement
        if squashed(corners, ref.size_px) \
                or quad_iou(corners, project_corners(ref, start)) < agreement:
            return False
        track.homography, track.corners, track.misses = aligned, corners, 0
        track.patch, track.outline_held = None, True  # whole and mostly in view
        track.saturated = self._over_exposed(track.landmark_id, image, corners)
        return True

    def _align_turned(self, track: Track, image: npt.NDArray[np.uint8],
                      motion: FloatArray) -> FloatArray | None:
        """The alignment from the last homography moved by the camera's turn: a cut
        plate's affine alignment from there alone (the frame's shift around it and its
        box's move are the turn's own, already in the start), a whole one's as usual."""
        assert track.homography is not None
        turned = motion @ track.homography
        turned = turned / turned[2, 2]
        if not self.is_cut(track.landmark_id, turned):
            return self.align(track, image, turned)
        return align_cut(self.references[track.landmark_id], image, turned,
                         self.config.ecc_iterations, TRACK_MIN_CORRELATION, self.weights(track))

    def align(self, track: Track, image: npt.NDArray[np.uint8], hom: FloatArray,
              verify: bool = False) -> FloatArray | None:
        """ECC alignment of the reference on the tracker's best colour feature (grey levels
        for a grey target), kept only if it agrees with the tracker's box (else the track
        is ``disputed``: its box is not used alone, see :func:`companion.tracks.observations`);
        with a ``partial_box`` (the part of a cut plate), with the outline it started from."""
        ref = self.references[track.landmark_id]
        tried = track.tried
        if not verify and tried is not None and np.array_equal(tried[0], hom):
            aligned = tried[1]  # the coast's alignment from this very start, this frame
        else:
            aligned = ecc(self.config, ref, image, hom, verify, self.weights(track))
        box = track.box
        if aligned is None:
            return None
        corners = project_corners(ref, aligned)
        if verify:  # from the box itself: its centre must lie on the plate found
            return aligned if centre_on(corners, box) else None
        predicted = project_corners(ref, hom)
        if not (quad_iou(corners, predicted) >= self.config.min_corner_agreement
                if track.partial_box else self._agrees(corners, predicted, box)):
            track.disputed = True  # the alignment or the box wandered off: drop the corners
            return None
        return aligned

    def _agrees(self, found: FloatArray, predicted: FloatArray, box: Box) -> bool:
        """The outline ``predicted`` moved with the tracker's ``box`` (centred on it)
        against the outline ``found``: a rotated plate's outline fills its axis-aligned
        box poorly, so outlines are compared, not boxes."""
        x, y, w, h = box
        moved = predicted + (np.array([x + w / 2, y + h / 2]) - predicted.mean(axis=0))
        return quad_iou(found, moved) >= self.config.min_corner_agreement

    def left_view(self, track: Track) -> bool:
        """Has the track's plate left the image (its last outline under ``LEFT_VIEW_SHARE``
        in view)?"""
        if track.homography is None:
            return False
        outline = track.corners if track.corners is not None else \
            project_corners(self.references[track.landmark_id], track.homography)
        return in_view_share(outline, self.camera.width, self.camera.height) < LEFT_VIEW_SHARE

    def is_cut(self, landmark_id: str, hom: FloatArray) -> bool:
        """Is the outline ``hom`` projects cut by the image's edge below
        ``min_corner_in_view`` (its tracker's box then holds only the part in view)?"""
        outline = project_corners(self.references[landmark_id], hom)
        share = in_view_share(outline, self.camera.width, self.camera.height)
        return share < self.config.min_corner_in_view

    def align_cut(self, track: Track, image: npt.NDArray[np.uint8], hom: FloatArray,
                  last_box: Box) -> FloatArray | None:
        """A cut plate's homography moved by the affine alignment of its part in view
        (tracker/edge_align.py): a full alignment on a corner region bends the rest.  It
        starts moved by the shift of the frame around the plate since the last frame
        (``track.patch``: the affine alignment holds a plate from where it is, not from a
        few pixels off); else where it was, then moved as the tracker's box moved since
        ``last_box`` (its edges inside the image): a plate sliding 10-20 px a frame is out
        of the affine alignment's reach (and a still one's box jitters by a pixel)."""
        ref = self.references[track.landmark_id]
        moved = None if track.patch is None else patch_shift(track.patch, image)
        dx, dy = box_shift(last_box, track.box, self.camera.width, self.camera.height)
        starts = ([] if moved is None else [shifted(hom, *moved)]) + [hom] + (
            [shifted(hom, dx, dy)] if max(abs(dx), abs(dy)) > 2.0 else [])
        for start in starts:
            aligned = align_cut(ref, image, start, self.config.ecc_iterations,
                                TRACK_MIN_CORRELATION, self.weights(track))
            if aligned is not None:
                return aligned
        return None

    def recover(self, track: Track, image: npt.NDArray[np.uint8]) -> None:
        """Get the homography back: align the reference onto the tracked box (held to
        ``verify_correlation``), else re-match its features around the box.  Alignment
        first: it is cheaper, and finds plates too small or plain for feature matching."""
        lid = track.landmark_id
        ref = self.references[lid]
        aligned = self.align(track, image, homography_to(ref, box_corners(track.box)),
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

    def check(self, track: Track, image: npt.NDArray[np.uint8]) -> float:
        """Check the track's landmark is still where its homography says, by its warped
        appearance: the correlation found (the track's fit sigma and failed checks are
        updated; the track's own state only)."""
        ref = self.references[track.landmark_id]
        hom = track.homography
        if hom is None:
            ncc, fit = 0.0, None
        elif track.corners is None:
            # no corners this frame: a whole plate's outline at its tracker's box, a few px
            # off; a cut plate's box holds only its part in view, so its outline stays put
            # while the box's centre is on it (real seed 41's real-01 leaving: a box 45 px
            # beside the plate, the outline right, is checked at the box and fails)
            on = track.partial_box and centre_on(project_corners(ref, hom), track.box)
            at = hom if on else moved_to_box(ref, hom, track.box)
            ncc, fit = check_appearance_near(ref, image, at, self._reach_px(track))
        else:
            ncc, fit = check_appearance(ref, image, hom)
        track.fit_sigma = fit if self.config.corner_sigma_from_fit else None
        track.verify_failures = 0 if ncc >= self.config.track_appearance_ncc \
            else track.verify_failures + 1
        return ncc

    def _reach_px(self, track: Track) -> int:
        """How far a box-placed outline is searched when checked: only for box-only tracking
        (``refine_corners`` off), where the box is all there is.  With corners on, a track
        whose alignment failed this frame is checked where its box says, as before: on the
        real-imagery world seed 3 the search kept such tracks alive and their bearings took
        the bearing_ls fixes from 0.13 to 0.37 m RMSE (docs/decisions.md)."""
        if self.config.refine_corners:
            return 0
        reach = self.config.box_check_reach_rel * min(track.box[2], track.box[3])
        return max(3, round(reach)) if reach > 0 else 0
