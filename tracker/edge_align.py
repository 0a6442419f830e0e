"""Keep a plate's homography while the image's edge cuts it (issue 19).

A full homography (8 parameters) aligned on the part of a plate still in view wanders: the
corners outside the image are extrapolations of a corner region, and the alignment bends
them (seen on the sample street: the corner inside the image stayed within 0.3 px while the
ones outside went 100-300 px off within a second, and the track was then dropped for its
appearance).  Between two frames a cut plate's image changes by little more than a shift
and a scale, so the last homography is only *moved* by the affine map (6 parameters) that
aligns its own rendering onto the new frame: what is out of view keeps its last shape.

That alignment holds a plate from where it was, but not from a few pixels off: on the
square's wall-02 leaving the image (26 -> 10 % in view, sliding 4.6 px a frame), started
from its true outline 2 px off it settled 3-18 px off, with a correlation that passed.  The
start is therefore moved first by the shift of the frame around the plate's part in view
since the last frame (:func:`patch_shift`, a phase correlation: the plate moves with the
wall it hangs on, whose texture and the plate's own edges are in that window): 0.1-0.3 px
from the truth on the same frames, and the alignment from there within 0.1-0.3 px.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from tracker.acquire import EccStart, Reference, Weights, ecc_start
from tracker.geometry import FloatArray

#: Fewest pixels of the plate in view that an alignment rests on.
MIN_PIXELS = 200
#: Largest change of scale, squash or shear a frame (:func:`stretch`; a rotation is none)
#: taken from a sliver of a cut plate; more is the alignment wandering on too little.
MAX_LINEAR_STEP = 0.03
#: A part in view on fewer pixels than this (a 63 px square) is a sliver, whose affine
#: step's stretch is held to ``MAX_LINEAR_STEP``; on more, the stretch is measured, not
#: wandering: the survey's hover flipped wall-04's outline on 400-3500 px (stretch 0.04-0.9
#: a frame, undone the next), the flown square's roll and entering plates stretch 0.04-0.3 on
#: 9600-17000 px, and holding those lost the plates.  Measured on the simulator's 640x480
#: frames only (docs/decisions.md, "A cut plate's stretch is held on a sliver only").
SLIVER_PIXELS = 4000
#: The window whose shift moves a cut plate's start: the box of its outline's part in view
#: widened by this many px (its edges and the wall around them).
PATCH_MARGIN_PX = 30
#: Smallest side of that window (px): less holds too little to correlate.
PATCH_MIN_SIDE_PX = 24
#: A shift whose phase-correlation response is below this is not trusted (the frame
#: changed more than it moved: a light step, another plate crossing).
MIN_SHIFT_RESPONSE = 0.3


@dataclass(frozen=True)
class Patch:
    """A frame's grey levels around a cut plate's part in view, and where they are."""

    grey: npt.NDArray[np.float32]
    x0: int
    y0: int


def patch_around(frame: npt.NDArray[np.uint8], corners: FloatArray) -> Patch | None:
    """The window of ``frame`` (BGR or grey) around the part in view of the outline
    ``corners``, ``PATCH_MARGIN_PX`` wider; None when too small."""
    height, width = frame.shape[:2]
    x0, y0 = np.clip(np.floor(corners.min(axis=0)) - PATCH_MARGIN_PX, 0, None).astype(int)
    x1 = int(min(np.ceil(corners[:, 0].max()) + PATCH_MARGIN_PX, width))
    y1 = int(min(np.ceil(corners[:, 1].max()) + PATCH_MARGIN_PX, height))
    if min(x1 - x0, y1 - y0) < PATCH_MIN_SIDE_PX:
        return None
    x1, y1 = x0 + _dft_side(x1 - x0), y0 + _dft_side(y1 - y0)
    return Patch(_grey(frame[y0:y1, x0:x1]), int(x0), int(y0))


def patch_shift(patch: Patch, frame: npt.NDArray[np.uint8]) -> tuple[float, float] | None:
    """How far ``frame``'s content moved (dx, dy px) in ``patch``'s window since the frame
    the patch was taken from (phase correlation, Hann-windowed); None when the response
    is under ``MIN_SHIFT_RESPONSE``."""
    h, w = patch.grey.shape
    now = _grey(frame[patch.y0:patch.y0 + h, patch.x0:patch.x0 + w])
    if now.shape != patch.grey.shape:
        return None
    (dx, dy), response = cv2.phaseCorrelate(patch.grey, now,
                                            cv2.createHanningWindow((w, h), cv2.CV_32F))
    return (float(dx), float(dy)) if response >= MIN_SHIFT_RESPONSE else None


def _dft_side(n: int) -> int:
    """The longest side up to ``n`` that is even and a size OpenCV's DFT takes unpadded:
    its phase correlation pads to such a size, and an odd one puts half a pixel into the
    shift (measured: an unmoved window 81 px high gave 0.5 px down, one 74 px wide, padded
    to 75, 0.5 px right)."""
    while n > 2 and (n % 2 or cv2.getOptimalDFTSize(n) != n):
        n -= 1
    return n


def _grey(crop: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
    grey = cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY) if crop.ndim == 3 else crop
    return np.asarray(grey, np.float32)


def _rendered(start: EccStart) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
    """The reference rendered into ``start``'s window at its warp, and the mask of where it
    lies (eroded by a pixel: its edge is interpolated with what is outside)."""
    roi_size = start.roi.shape[1::-1]
    rendered = cv2.warpPerspective(start.template, start.warp, roi_size,
                                   flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    mask = cv2.erode(cv2.warpPerspective(np.ones(start.template.shape, np.uint8), start.warp,
                                         roi_size, flags=cv2.INTER_NEAREST),
                     np.ones((3, 3), np.uint8))
    return np.asarray(rendered, np.float32), np.asarray(mask, np.uint8)


def align_cut(ref: Reference, frame: npt.NDArray[np.uint8], hom: FloatArray,
              iterations: int = 30, min_correlation: float = 0.6,
              weights_bgr: Weights | None = None) -> FloatArray | None:
    """``hom`` (reference -> frame, last frame's) moved by the affine map that best aligns
    the reference rendered through it onto ``frame``, inside the image only; None when too
    little is in view, ECC fails or its correlation stays under ``min_correlation``.

    ``frame`` is grey or BGR; with ``weights_bgr`` (BGR) aligned on that colour feature,
    as :func:`tracker.acquire.refine_ecc`."""
    start = ecc_start(ref, frame, hom, weights_bgr)
    if start is None:
        return None
    roi = start.roi
    rendered, mask = _rendered(start)
    pixels = int(np.count_nonzero(mask))
    if pixels < MIN_PIXELS:
        return None
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, 1e-5)
    try:  # the shift first (a wide basin), then the affine map from there
        cc, shift = cv2.findTransformECC(rendered, roi, np.eye(2, 3, dtype=np.float32),
                                         cv2.MOTION_TRANSLATION, criteria, mask, 5)
        # a copy: findTransformECC writes its result into the warp it starts at
        cc, affine = cv2.findTransformECC(rendered, roi, shift.copy(), cv2.MOTION_AFFINE,
                                          criteria, mask, 1)
    except cv2.error:
        return None
    if float(cc) < min_correlation or not np.all(np.isfinite(affine)):
        return None
    if pixels < SLIVER_PIXELS and stretch(affine) > MAX_LINEAR_STEP:
        affine = shift  # a sliver's affine map wandered (scale, squash, shear): keep the shift
    to_roi = np.linalg.inv(start.from_roi)
    moved = start.from_roi @ np.vstack([affine, (0.0, 0.0, 1.0)]) @ to_roi @ hom
    return np.asarray(moved / moved[2, 2], np.float64)


def stretch(affine: npt.ArrayLike) -> float:
    """How far an affine map (2x3) scales, squashes or shears: its linear part's singular
    values off 1 (the largest).  A rotation stretches nothing: a camera rolling turns a cut
    plate by degrees a frame (the strict square), which its affine step must follow; a
    sliver's stretch is the alignment wandering (the survey's hover: a fifth of wall-04 in
    view flipped between two outlines frame by frame, docs/decisions.md)."""
    values = np.linalg.svd(np.asarray(affine, np.float64)[:, :2], compute_uv=False)
    return float(np.abs(values - 1.0).max())


def search_shift(ref: Reference, frame: npt.NDArray[np.uint8], hom: FloatArray,
                 radius_px: float, min_correlation: float = 0.6) -> tuple[float, float] | None:
    """Where the part in view of ``ref`` rendered at ``hom`` matches ``frame`` best within
    ``radius_px`` of it: the shift (dx, dy px, whole pixels) of the highest normalised
    correlation (masked to the plate's part in view; the frame's border replicated beyond the
    image), or None when that stays under ``min_correlation`` or too little is in view.

    :func:`align_cut`'s ECC holds a plate from a few pixels off, not from an autopilot's
    estimate up to tens of pixels off: this exhaustive search over the shifts gives it a
    start (issue 19: the square's plates entering the view while nothing is tracked)."""
    start = ecc_start(ref, frame, hom)
    if start is None:
        return None
    rendered, mask = _rendered(start)
    ys, xs = np.nonzero(mask)
    if len(xs) < MIN_PIXELS:
        return None
    bx0, bx1, by0, by1 = int(xs.min()), int(xs.max()) + 1, int(ys.min()), int(ys.max()) + 1
    r = int(np.ceil(radius_px))
    x0, y0 = int(start.from_roi[0, 2]) + bx0, int(start.from_roi[1, 2]) + by0  # in the frame
    grey = cv2.copyMakeBorder(_grey(frame), r, r, r, r, cv2.BORDER_REPLICATE)
    search = grey[y0:y0 + by1 - by0 + 2 * r, x0:x0 + bx1 - bx0 + 2 * r]
    score = cv2.matchTemplate(search, np.ascontiguousarray(rendered[by0:by1, bx0:bx1]),
                              cv2.TM_CCOEFF_NORMED, mask=mask[by0:by1, bx0:bx1])
    score = np.nan_to_num(score, nan=-1.0, posinf=-1.0, neginf=-1.0)
    iy, ix = np.unravel_index(int(np.argmax(score)), score.shape)
    if float(score[iy, ix]) < min_correlation:
        return None
    return float(ix - r), float(iy - r)


def box_shift(old: tuple[float, float, float, float], new: tuple[float, float, float, float],
              width: int, height: int, margin: float = 1.0) -> tuple[float, float]:
    """How far a cut plate moved between two of its tracker's boxes ``(x, y, w, h)``: per
    axis, the move of an edge inside the image in both (the edges at the image's border
    stay there while the plate slides under it); 0 when neither edge is."""
    def axis(a0: float, a1: float, b0: float, b1: float, size: int) -> float:
        if a0 > margin and b0 > margin:
            return b0 - a0
        if a1 < size - margin and b1 < size - margin:
            return b1 - a1
        return 0.0
    (ox, oy, ow, oh), (nx, ny, nw, nh) = old, new
    return (axis(ox, ox + ow, nx, nx + nw, width), axis(oy, oy + oh, ny, ny + nh, height))


def shifted(hom: FloatArray, dx: float, dy: float) -> FloatArray:
    """``hom`` followed by a shift of (dx, dy) px in the frame."""
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]]) @ hom
