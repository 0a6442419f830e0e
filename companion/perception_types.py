"""The perception's values: its configuration, tracks and what other parts hand it.

Split from :mod:`companion.perception` (which re-exports them) to keep that module
readable; nothing here runs anything.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from tracker import AdaptiveTracker
from tracker.acquire import BAND_FROM_PX, Weights
from tracker.boxes import box_cover
from tracker.edge_align import Patch
from tracker.features import colour_weights
from tracker.types import Box

FloatArray = npt.NDArray[np.float64]
COLOUR_WEIGHTS = colour_weights()  # (49, 3) (w_r, w_g, w_b): the tracker's colour features


@dataclass(frozen=True)
class PerceptionConfig:
    """How often to look for untracked landmarks and how far to trust a track."""

    acquire_every_frames: int = field(default=15, metadata={"ge": 1})
    acquire_every_frames_with_fix: int = field(default=60, metadata={"ge": 1})
    max_tracks: int = field(default=8, metadata={"ge": 1})
    min_track_confidence: float = field(default=0.2, metadata={"ge": 0, "le": 1})
    refine_corners: bool = True
    #: A camera turn between two frames of this many degrees or more (the autopilot's
    #: attitude at both) starts the corners' alignment from the last outline moved by the
    #: turn's homography (companion/ego_motion.py; 0: never); smaller turns move a plate
    #: by a few px, which the alignment takes up from where it was.  Off by default: it
    #: needs the attitude on the frames' clock (config/sim.toml turns it on)
    predict_turn_deg: float = field(default=0.0, metadata={"ge": 0})
    min_corner_agreement: float = field(default=0.5, metadata={"gt": 0, "le": 1})
    ecc_iterations: int = field(default=10, metadata={"ge": 1})
    #: Unsmoothed ECC iterations after the smoothed ones (tracker.acquire.refine_ecc).
    ecc_fine_iterations: int = field(default=6, metadata={"ge": 0})
    #: The unsmoothed stage leaves out the reference's outer ring of this many pixels
    #: (0: none): there the frame mixes in what is behind the plate (docs/pose.md).
    ecc_edge_band_px: int = field(default=1, metadata={"ge": 0, "le": 8})
    #: ... of a template (the reference at the plate's size in the frame) whose short side
    #: is at least this many pixels (1: every one; 48 until 2026-12-05, docs/decisions.md,
    #: "A small plate's ring is left out too").
    ecc_band_from_px: int = field(default=BAND_FROM_PX, metadata={"ge": 1})
    #: ... and aligns a colour feature mixed with this share of grey levels: a camera keeps
    #: chroma at half resolution, grey levels at full (tracker.acquire.mixed_weights).
    ecc_fine_grey_share: float = field(default=0.5, metadata={"ge": 0, "le": 1})
    #: ... or grey levels alone, on a plate whose luma's gradient energy is at least this
    #: many times its chroma's (tracker.acquire.luma_chroma_ratio; 0: never).  Under JPEG
    #: a photograph's mixed plane is mostly chroma error and held its corners 0.1-0.4 px
    #: off along one outline mode for a whole track (docs/decisions.md, "Grey levels alone
    #: on a plate with little colour").  Measured on simulated JPEG frames only: 0 (off) in
    #: the deployment, 4 in the simulator's layer (config/sim.toml).
    ecc_grey_from_ratio: float = field(default=0.0, metadata={"ge": 0})
    #: A track's corners feed the pose only while this share of its quadrilateral is in
    #: the image: corners extrapolated from a sliver are off by pixels.
    min_corner_in_view: float = field(default=0.6, metadata={"ge": 0, "le": 1})
    #: A plate whose outline crosses the image's edge (cut, or mostly in view), followed
    #: for fewer than ``young_cut_frames`` frames, states its corners no better than
    #: ``young_cut_sigma_rel`` of its outline's size (the square root of its area): the
    #: first outlines of a plate acquired at the edge (by its features, or aligned from the
    #: autopilot's estimate) are unsettled. On the flown square their lone fixes were
    #: 0.3-1.7 m off at a stated 0.02-0.14 m in their first 0.3 s, and the strict fake's
    #: estimate followed them (docs/decisions.md, "A young cut plate states its corners
    #: loosely").
    young_cut_frames: int = field(default=9, metadata={"ge": 0})
    young_cut_sigma_rel: float = field(default=0.05, metadata={"ge": 0})
    #: A plate under ``min_corner_in_view`` in view states the corners its outline puts
    #: outside the image as weak points, at this share of the outline's size (the square
    #: root of its area; 0: left out).  Its alignment on the part in view carries the
    #: outline out of the image, and those corners hold the plate's scale and turn: with
    #: one corner inside, the fix rested on that corner's bearing alone, 1.6-3.9 m stated,
    #: and the strict fake drifted 0.3-0.6 m on its IMU while hovering at the square's
    #: (6, 6) (docs/decisions.md, "A cut plate's extrapolated corners are weak points").
    #: It can make a fix more certain and was measured on rendered plates only: 0 (off) in
    #: the deployment, 0.05 in the simulator's layer (config/sim.toml).
    cut_extrapolated_sigma_rel: float = field(default=0.0, metadata={"ge": 0})
    #: ... and while at most this share of its pixels is saturated: over-exposed plates
    #: (58 % of their pixels at 255) put the corners 0.4 px off, 4x the error of the same
    #: plate in normal light (docs/pose.md).  White print on a plate saturates 0-4 %.
    max_corner_saturated: float = field(default=0.25, metadata={"ge": 0, "le": 1})
    #: Corner 1-sigma by plate size: ``pose.pixel_sigma_px`` for a plate
    #: ``corner_sigma_ref_px`` wide, times (that width / the plate's) ** this exponent
    #: (0: one sigma for all).  Alignment has fewer pixels to go by on a small plate.
    corner_sigma_exponent: float = field(default=0.8, metadata={"ge": 0, "le": 2})
    corner_sigma_ref_px: float = field(default=100.0, metadata={"gt": 0})
    #: 1-sigma (px) of an error the four corners share, scaling the plate about its centre
    #: (given as the change of its width; ``Observation.corner_scale_sigma_px``; times the
    #: rectification's stretch).  The alignment draws outlines in as a whole (plate widths
    #: 0.15-0.22 px short on average in every rendered scenario), but with the width-only
    #: corner sigma no setting tried kept every scenario's fixes consistent (docs/pose.md,
    #: "Corner errors are not independent"), so it is off: corners independent.
    corner_scale_sigma_px: float = field(default=0.0, metadata={"ge": 0})
    #: The corners' 1-sigma is the larger of the size model above and the alignment's own
    #: fit (tracker.verify.fit_corner_sigma: residual and gradient of the warped appearance).
    corner_sigma_from_fit: bool = True
    #: ... and a track's corners are not used when the fit's sigma exceeds the size model's
    #: by this factor: the alignment sits wrong on the plate (a real crop's corners 2-8 px
    #: off with a fit sigma 3-9x the model's, where the plates aligned right had <= 1.2x).
    max_fit_sigma_ratio: float = field(default=2.5, metadata={"gt": 1})
    #: The fit sigma times this is stated: the fit knows the noise, not the bias JPEG and
    #: resampling leave (real crops' corner errors were ~1.5x the fit sigma, RMS).
    fit_sigma_scale: float = field(default=2.0, metadata={"ge": 1})
    #: A plate aligned on grey levels alone (``ecc_grey_from_ratio``) states its corners at
    #: the fit sigma times ``fit_sigma_scale`` only, not at the larger of that and the size
    #: model, which was fitted on mixed-plane corners (grey-aligned corners erred 0.50-0.75
    #: of it on real-imagery worlds).  Off in the deployment, on in config/sim.toml.
    grey_fit_sigma: bool = False
    #: A plate aligned on the mixed plane (not on grey levels alone) on a lossy frame
    #: (``Frame.lossy``: JPEG, video): its outline's eight modes over its corners' sigma in
    #: a fix of several plates, as ``pose.corner_mode_sigma_rel`` (which a mode at 0 here
    #: takes, and every grey-aligned plate, and every plate of a lossless frame).  The two
    #: alignments err differently, and a codec moves a rendered plate's edges; the
    #: simulator's layer measures each (docs/decisions.md, "A plate's modes by its
    #: alignment", "... on lossy frames").
    lossy_mixed_corner_mode_sigma_rel: tuple[float, float, float, float, float, float,
                                             float, float] = field(default=(0.0,) * 8,
                                                                   metadata={"ge": 0})
    #: ... and no less than what the track's corners have really missed by: the RMS of
    #: their reprojection residuals in fixes from two or more plates (corrected for the
    #: six pose parameters fitted to them), averaged over about ``residual_sigma_fixes``
    #: fixes (0: off).  JPEG moves edges (0.39 px against 0.11 px on PNG, survey world)
    #: and a real crop can sit biased (0.6-0.8 px) where neither the size model nor the fit
    #: sees it; the other plates do (docs/decisions.md, issue 25).
    residual_sigma_fixes: float = field(default=10.0, metadata={"ge": 0})
    #: A plate that is the frame's only one with corners has them taken less their steady
    #: error along its outline's eight modes (shift, rotation, scale, aspect, shear,
    #: perspective: tracker.pose.inputs.outline_basis), averaged over about this many of its
    #: residuals in fixes of two or more plates, once half as many are in (0: off).  A real
    #: crop's corners sit 1-2 sigma off in the same modes for hundreds of frames; in a fix of
    #: several plates the others outvote that, but a lone plate's fix carries it whole
    #: (docs/decisions.md, "A lone plate's steady corner error, learnt beside other plates").
    #: Not taken off when other plates' corners are in the fix: two plates' residuals split
    #: their disagreement, and a correction learnt from them moved good fixes (real seed 10).
    corner_bias_fixes: float = field(default=0.0, metadata={"ge": 0})
    #: A plate's corners with a share ``s`` of its pixels saturated state their sigma times
    #: ``1 + saturated_sigma_gain * s``: sudden_light's plates 50-60 % saturated (160 %
    #: light) had corners 0.41 px off against 0.10 px unsaturated, 4x (docs/pose.md).
    saturated_sigma_gain: float = field(default=5.5, metadata={"ge": 0})
    #: A track whose corners the pose solver left out of this many fixes in a row (they
    #: disagreed with the other landmarks') is dropped, to be acquired afresh (0: never;
    #: docs/reliability.md finding 4: a re-acquired track kept corners 12.7 sigma off).
    max_pose_rejections: int = field(default=15, metadata={"ge": 0})
    #: Every new track is verified by its appearance warped by the homography found: the
    #: normalised correlation of its detail with the frame's (light-normalised,
    #: tracker.verify.detail_ncc) must reach this.
    min_appearance_ncc: float = field(default=0.65, metadata={"gt": 0, "le": 1})
    #: ... and so must each quarter of the plate that has detail of its own
    #: (tracker.verify.part_nccs): an outline placed by a look-alike's features on the part
    #: the two photographs share hangs off the plate on one side, where it correlates
    #: with the ground (0.29 measured), while on its plate every quarter reached 0.54 or
    #: more (docs/decisions.md, "One place, one landmark").  0: not checked.
    min_part_ncc: float = field(default=0.4, metadata={"ge": 0, "le": 1})
    #: Every this many frames each track is checked the same way; under
    #: ``track_appearance_ncc`` (or without corners) it is unverified: left out of the fix,
    #: and dropped after ``max_verify_failures`` checks in a row.
    verify_every_frames: int = field(default=5, metadata={"ge": 1})
    track_appearance_ncc: float = field(default=0.5, metadata={"gt": 0, "le": 1})
    max_verify_failures: int = field(default=2, metadata={"ge": 1})
    #: Box-only tracking (``refine_corners`` off): a track is checked where its tracker box
    #: puts the outline, and the box's centre is a few pixels off the plate's: the check
    #: takes the best whole-pixel shift within this share of the box's short side (at
    #: least 3 px; tracker/verify.py check_appearance_near).  0: where it is placed.
    #: Geometry, not a tuned value: the tracker's centre error (docs/tracker.md) is of
    #: that size.  With corners on, a track without corners this frame is checked in place.
    box_check_reach_rel: float = field(default=0.1, metadata={"ge": 0, "le": 0.5})
    #: The frame's mean grey level changing by more than this factor from one frame to the
    #: next is a light step: every track is checked at once and acquisition runs at once.
    light_step_ratio: float = field(default=1.25, metadata={"gt": 1})
    max_corner_misses: int = field(default=5, metadata={"ge": 1})
    #: The particle tracker runs on one frame in this many while a whole plate's corners
    #: are aligned; on the others its box follows the outline the alignment found from
    #: the last one (which checks it against that outline, not against the tracker's box)
    #: and the tracker looks at nothing (issue 23: the tracker was ~40 % of a frame's CPU
    #: and the corners come from the alignment either way).  1: every frame.
    track_every_frames: int = field(default=3, metadata={"ge": 1})
    verify_correlation: float = field(default=0.75, metadata={"gt": 0, "le": 1})
    max_prediction_error_px: float = field(default=12.0, metadata={"gt": 0})
    #: Without a fix, a plate the autopilot's estimate predicts cut by the image's edge with
    #: at least this share of it in view is looked for by aligning its part in view (issue
    #: 19: a plate entering from the edge was acquired only once ~0.7 of it was in view);
    #: 1: only whole plates.
    predict_cut_in_view: float = field(default=0.25, metadata={"gt": 0, "le": 1})
    #: Without a fix, landmarks are predicted from the autopilot's own pose estimate; an
    #: alignment found further than this from that prediction is not taken.
    max_guess_error_px: float = field(default=30.0, metadata={"gt": 0})
    #: Without a fix for this long, search the whole frame for one landmark per frame.
    search_after_s: float = field(default=0.3, metadata={"ge": 0})
    #: Once nothing has been tracked for ``idle_after_s`` (from the start: at once), feature
    #: matching and the whole-frame search run on one frame in ``idle_search_every_frames``
    #: instead of back to back: with nothing in view they took a core (issue 23; each
    #: call costs 20-100 ms of CPU) for a landmark found at most that many frames later.
    #: A track just lost is searched for at the full rate until then.  1: every frame.
    idle_after_s: float = field(default=1.0, metadata={"ge": 0})
    idle_search_every_frames: int = field(default=6, metadata={"ge": 1})
    search_min_score: float = field(default=0.5, metadata={"gt": 0, "le": 1})
    search_widths_px: tuple[float, ...] = (40.0, 60.0, 90.0, 135.0, 200.0, 300.0)
    #: Without a fix, acquire with the landmark detector ([detector]) first, the template
    #: search when its detections start no track.
    use_detector: bool = True
    #: Update the tracks of one frame on two threads (OpenCV and most of numpy release
    #: the GIL): lower latency with several landmarks in view, the same CPU time.
    parallel_tracks: bool = True
    #: With ``parallel_tracks``, keep the frame worker and the second track thread on a
    #: core each (the process's last two) while other processes leave those cores free
    #: and the threads do not wait for them (:mod:`companion.cores`, Linux only).
    keep_frame_cores: bool = True


class DetectionLike(Protocol):
    """What acquisition needs of a detector hit (tracker.detector.Detection has it)."""

    @property
    def box(self) -> tuple[float, float, float, float]: ...
    @property
    def category(self) -> str: ...
    @property
    def score(self) -> float: ...


#: A detector: image -> detections (``tracker.detector.Detector.detect``).
DetectFn = Callable[[npt.NDArray[np.uint8]], Sequence[DetectionLike]]


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
    misses: int = 0
    #: share of the aligned quadrilateral's pixels that are saturated in this frame
    saturated: float = 0.0
    #: the colour feature the corners are aligned on: the tracker's best at acquisition,
    #: when the box was verified (None: grey levels)
    align_weights: Weights | None = None
    #: corner 1-sigma (px) from the alignment's fit at the last check (None: not known)
    fit_sigma: float | None = None
    #: mean squared corner reprojection residual (px^2, per coordinate, corrected for the
    #: pose's parameters) over recent fixes from two or more plates (None: none yet)
    residual_var: float | None = None
    #: the corners' mean residual along the outline's eight modes (px) in recent fixes from
    #: two or more plates (None: none yet), and how many fixes taught it
    bias_modes: FloatArray | None = None
    bias_fixes: int = 0
    #: fixes in a row that left this track's corners out
    pose_rejections: int = 0
    #: appearance checks failed in a row (0: the last check found the landmark)
    verify_failures: int = 0
    #: the tracker's box disagreed with the outline the alignment found (which was then
    #: dropped), and no alignment has held since: the box is not used for a box-only fix
    disputed: bool = False
    #: this frame's coast alignment (its start, its result: None when ECC failed), reused by
    #: ``Corners.align`` from the same start instead of the same ECC run again
    tried: tuple[FloatArray, FloatArray | None] | None = None
    #: frames in a row on which the tracker coasted (``track_every_frames``)
    coasted: int = 0
    #: the last frame around a plate cut by the image's edge (None: not cut), whose shift
    #: starts the next frame's alignment (tracker/edge_align.py)
    patch: Patch | None = None
    #: the tracker's box was seated on a plate cut by the image's edge: it holds the part
    #: that was in view, not the plate (``Corners`` re-seats it once the plate is whole)
    partial_box: bool = False
    #: the outline's part out of the image keeps the shape it had when the plate was last
    #: mostly in view: aligned frame to frame since (``Corners.align_cut`` or whole), its
    #: size never jumping (``companion.corners.HELD_SIZE_STEP``); not after an outline found
    #: afresh on a cut plate (``Corners.recover``), which the part in view does not hold
    outline_held: bool = False
    #: frames this track has been followed since it was acquired
    frames: int = 0
    #: CPU (s) of its last update, to share the next frame's updates between two threads
    cost_s: float = 0.0


@dataclass(frozen=True, eq=False)
class TrackView:
    """What a frame's result says of one track (``FrameResult.tracks``): a frozen copy, made
    on the worker thread as the frame's update ends, so whoever reads it later (the reporter,
    the preview on the background lane, an observer) sees that frame's track and nothing
    the next frame changes.  Its monitoring JSON is :func:`companion.reporting.track_json`."""

    landmark_id: str
    box: Box
    confidence: float
    features: tuple[int, ...]
    #: the four aligned corners (px, (4, 2), read-only, the alignment's own dtype), None
    #: when the alignment does not hold this frame
    corners: FloatArray | None

    @classmethod
    def of(cls, track: Track) -> TrackView:
        corners = None
        if track.corners is not None:
            corners = track.corners.copy()
            corners.flags.writeable = False
        return cls(track.landmark_id, track.box, track.confidence, tuple(track.features),
                   corners)


@dataclass(frozen=True)
class Start:
    """A tracker started by housekeeping, waiting for ``process`` to adopt it."""

    track: Track
    event: dict[str, Any]


@dataclass(frozen=True)
class Occupancy:
    """What housekeeping knows of the tracks: a snapshot the track set takes under its lock
    (:meth:`companion.tracks.TrackSet.snapshot`), never the live tracks themselves."""

    #: landmarks with a live track
    tracked: frozenset[str] = frozenset()
    #: landmarks started by housekeeping, not yet adopted by ``process`` (in order)
    waiting: tuple[str, ...] = ()
    #: the boxes of those tracks, running and waiting: the places taken
    places: tuple[Box, ...] = ()

    def busy(self, starts: Sequence[Start] = ()) -> int:
        """Tracks running, waiting to be adopted and just started."""
        return len(self.tracked) + len(self.waiting) + len(starts)

    def taken(self, lid: str, starts: Sequence[Start] = ()) -> bool:
        """Tracked, waiting to be adopted, or just started."""
        return lid in self.tracked or lid in self.waiting or any(
            s.track.landmark_id == lid for s in starts)

    def crowded(self, box: Box, starts: Sequence[Start] = ()) -> bool:
        """``box`` is a place another track holds (or one just started): the smaller of
        the two boxes lies in the other by :data:`PLACE_COVER` or more.  One place shows
        one landmark; a second landmark found there is a look-alike's features on the plate
        already tracked.  Not by IoU: a look-alike cut from the same photograph has its
        outline reach past the plate it matched, larger (real seed 62: IoU 0.49 with the
        plate's box, 77 % of that box inside; docs/decisions.md, "One place by half of
        the plate's box")."""
        taken = (*self.places, *(s.track.box for s in starts))
        return any(box_cover(box, other) >= PLACE_COVER for other in taken)


#: Two tracks' boxes, the smaller this much inside the other, are on one place
#: (:meth:`Occupancy.crowded`).
PLACE_COVER = 0.5

#: ECC correlation a running track's alignment must reach (a new sighting: verify_correlation).
TRACK_MIN_CORRELATION = 0.6


def feature_weights_bgr(features: Sequence[int]) -> Weights | None:
    """(w_b, w_g, w_r) of the tracker's best colour feature; None for grey cues or none."""
    if not features or features[0] >= len(COLOUR_WEIGHTS):
        return None
    r, g, b = (float(v) for v in COLOUR_WEIGHTS[features[0]])
    return (b, g, r)
