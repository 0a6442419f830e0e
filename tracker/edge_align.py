"""Keep a plate's homography while the image's edge cuts it (issue 19).

A full homography (8 parameters) aligned on the part of a plate still in view wanders: the
corners outside the image are extrapolations of a corner region, and the alignment bends
them (seen on the sample street: the corner inside the image stayed within 0.3 px while the
ones outside went 100-300 px off within a second, and the track was then dropped for its
appearance).  Between two frames a cut plate's image changes by little more than a shift
and a scale, so the last homography is only *moved* by the affine map (6 parameters) that
aligns its own rendering onto the new frame: what is out of view keeps its last shape.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from tracker.acquire import Reference, Weights, ecc_start
from tracker.geometry import FloatArray

#: Fewest pixels of the plate in view that an alignment rests on.
MIN_PIXELS = 200
#: Largest change of scale, squash or shear a frame (the affine map's linear part less the
#: identity) taken from a cut plate; more is the alignment wandering on too little.
MAX_LINEAR_STEP = 0.03


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
    plane, roi, warp = start.template, start.roi, start.warp
    roi_size = roi.shape[1::-1]
    rendered = cv2.warpPerspective(plane, warp, roi_size, flags=cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_REPLICATE)
    mask = cv2.erode(cv2.warpPerspective(np.ones(plane.shape, np.uint8), warp, roi_size,
                                         flags=cv2.INTER_NEAREST), np.ones((3, 3), np.uint8))
    if int(np.count_nonzero(mask)) < MIN_PIXELS:
        return None
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, 1e-5)
    rendered = np.asarray(rendered, np.float32)
    try:  # the shift first (a wide basin), then the affine map from there
        cc, affine = cv2.findTransformECC(rendered, roi, np.eye(2, 3, dtype=np.float32),
                                          cv2.MOTION_TRANSLATION, criteria, mask, 5)
        shift = affine.copy()
        cc, affine = cv2.findTransformECC(rendered, roi, shift, cv2.MOTION_AFFINE, criteria,
                                          mask, 1)
    except cv2.error:
        return None
    if float(cc) < min_correlation or not np.all(np.isfinite(affine)):
        return None
    if float(np.abs(affine[:, :2] - np.eye(2)).max()) > MAX_LINEAR_STEP:
        affine = shift  # a sliver's affine map wandered (shear, squash): keep the shift
    to_roi = np.linalg.inv(start.from_roi)
    moved = start.from_roi @ np.vstack([affine, (0.0, 0.0, 1.0)]) @ to_roi @ hom
    return np.asarray(moved / moved[2, 2], np.float64)


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
