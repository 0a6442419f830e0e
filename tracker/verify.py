"""Is the landmark really there, and how well are its corners known?

Both questions are answered by the landmark's appearance image warped by the homography
found (reference -> frame) and laid over the frame:

* :func:`appearance_ncc`: the normalised correlation of the warped appearance with the
  frame inside the outline (zero mean, unit variance on both: a change of light, gain and
  offset, does not change it).  A wall, a road or a neighbouring plate correlates poorly
  with a textured photograph; the plate itself correlates well whatever the light.
* :func:`fit_corner_sigma`: the corners' 1-sigma from the alignment's own fit, the
  Gauss-Newton covariance ``s^2 (J^T J)^-1`` of the eight corner coordinates, ``J`` the
  frame's gradient times how each pixel moves with each corner, ``s^2`` the residual
  variance after the best gain and offset, inflated for the residual's correlation
  between neighbouring pixels (JPEG blocks, resampling): ``(1 + r) / (1 - r)`` per axis,
  ``r`` the lag-one autocorrelation.  A sharp, well-fitting plate gets a small sigma, a
  blurred, badly fitting or plain one a large sigma.

Pure functions of images and matrices (no state).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from tracker.acquire import (
    Reference,
    homography_to,
    outline_window,
    project_corners,
    reference_template,
    resize_map,
    size_in_frame,
)

FloatArray = npt.NDArray[np.float64]
#: Fewer pixels than this inside the outline: too small to judge.
MIN_PIXELS = 64
#: A quarter of a plate is judged by :func:`part_nccs` when its detail has at least this
#: share of the whole plate's (standard deviation).
PART_DETAIL_SHARE = 0.5
#: Corner step (px) of the numerical derivative of the pixel positions.
STEP_PX = 0.5
#: The correlation inflation is capped (a nearly constant residual says nothing more).
MAX_INFLATION = 25.0
#: The fit's information is summed over at most about this many pixels (a sample).
MAX_JACOBIAN_PIXELS = 1500


@dataclass(frozen=True)
class Overlay:
    """The appearance warped into a region of the frame: both as float grey levels, the
    pixels inside the outline (eroded by one pixel: edge pixels mix in the background),
    the region's top-left in the frame."""

    template: npt.NDArray[np.float32]
    frame: npt.NDArray[np.float32]
    mask: npt.NDArray[np.bool_]
    origin: tuple[int, int]
    #: which quarter of the reference (0-3: top-left, top-right, bottom-left, bottom-right)
    #: each region pixel shows (:func:`part_nccs`); None: not asked for
    parts: npt.NDArray[np.uint8] | None = None


def overlay(ref: Reference, frame_bgr: npt.NDArray[np.uint8], hom: FloatArray,
            parts: bool = False) -> Overlay | None:
    """The reference (grey, scaled to about its size in the frame first) warped by ``hom``
    over the frame region around its outline; None when (almost) nothing is in view."""
    corners = project_corners(ref, hom)
    if not np.all(np.isfinite(corners)):
        return None
    height, width = frame_bgr.shape[:2]
    window = outline_window(corners, width, height, 2.0, 6)
    if window is None:
        return None
    x0, y0, x1, y1 = window
    w, h = ref.size_px
    size = size_in_frame(ref, corners, 6)
    small = reference_template(ref, None, size)
    to_roi = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]])
    warp = to_roi @ hom @ np.linalg.inv(resize_map((w, h), size))
    roi_size = (x1 - x0, y1 - y0)
    template = cv2.warpPerspective(small, warp, roi_size, flags=cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_REPLICATE)
    inside = cv2.warpPerspective(np.ones(small.shape, np.uint8), warp, roi_size,
                                 flags=cv2.INTER_NEAREST)
    inside = cv2.erode(inside, np.ones((3, 3), np.uint8))
    mask = inside.astype(bool)
    if int(mask.sum()) < MIN_PIXELS:
        return None
    crop = frame_bgr[y0:y1, x0:x1]
    grey = cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY) if crop.ndim == 3 else crop
    quarters = None
    if parts:
        sw, sh = size
        label = np.zeros((sh, sw), np.uint8)
        label[:, sw // 2:] += 1
        label[sh // 2:, :] += 2
        quarters = np.asarray(cv2.warpPerspective(label, warp, roi_size,
                                                  flags=cv2.INTER_NEAREST), np.uint8)
    return Overlay(np.asarray(template, np.float32), np.asarray(grey, np.float32), mask,
                   (x0, y0), quarters)


def appearance_ncc(ref: Reference, frame_bgr: npt.NDArray[np.uint8], hom: FloatArray
                   ) -> float:
    """Normalised correlation of the warped appearance with the frame (-1..1; 0 when
    nothing of it is in view or either side is flat)."""
    ov = overlay(ref, frame_bgr, hom)
    return 0.0 if ov is None else _ncc(ov)


def check_appearance(ref: Reference, frame_bgr: npt.NDArray[np.uint8], hom: FloatArray
                     ) -> tuple[float, float | None]:
    """(:func:`detail_ncc`, :func:`fit_corner_sigma`) from one overlay."""
    ov = overlay(ref, frame_bgr, hom)
    if ov is None:
        return 0.0, None
    return _ncc(_detail(ov)), _fit_sigma(ref, hom, ov)


def check_appearance_near(ref: Reference, frame_bgr: npt.NDArray[np.uint8], hom: FloatArray,
                          reach_px: int) -> tuple[float, float | None]:
    """:func:`check_appearance` at the best whole-pixel shift of ``hom`` within
    ``reach_px`` px (by :func:`best_shift`): for an outline placed by a tracker's box, whose
    centre is a few pixels off.  The detail correlation of a textured plate falls from 0.9
    to about 0 at 4-6 px off (sitl_tests/test_one_landmark.py, box-only tracks: 0.02-0.14
    where placed, 0.71-0.95 within 6 px), so without the search every box-only track
    failed its checks and was dropped about every half second."""
    if reach_px <= 0:
        return check_appearance(ref, frame_bgr, hom)
    dx, dy = best_shift(ref, frame_bgr, hom, reach_px)
    moved = np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]]) @ hom
    return check_appearance(ref, frame_bgr, moved)


def best_shift(ref: Reference, frame_bgr: npt.NDArray[np.uint8], hom: FloatArray,
               reach_px: int) -> tuple[int, int]:
    """The whole-pixel shift (dx, dy), each within ``reach_px``, at which the warped
    appearance's detail (:func:`detail_ncc`'s) correlates best with the frame's, by one
    masked normalised template match; (0, 0) when nothing can be compared."""
    ov = None if reach_px <= 0 else overlay(ref, frame_bgr, hom)
    if ov is None:
        return 0, 0
    ys, xs = np.nonzero(ov.mask)
    top, bottom, left, right = int(ys.min()), int(ys.max()) + 1, int(xs.min()), int(xs.max()) + 1
    x0, y0 = ov.origin[0] + left - reach_px, ov.origin[1] + top - reach_px
    x1, y1 = ov.origin[0] + right + reach_px, ov.origin[1] + bottom + reach_px
    height, width = frame_bgr.shape[:2]
    if x0 < 0 or y0 < 0 or x1 > width or y1 > height:  # at the edge: compare where it is
        return 0, 0
    crop = frame_bgr[y0:y1, x0:x1]
    grey = np.asarray(cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY) if crop.ndim == 3 else crop,
                      np.float32)
    sigma = _detail_sigma(ov.mask)
    region = grey - cv2.GaussianBlur(grey, (0, 0), sigma)
    template = ov.template - cv2.GaussianBlur(ov.template, (0, 0), sigma)
    mask = ov.mask[top:bottom, left:right].astype(np.float32)
    scores = cv2.matchTemplate(region, np.ascontiguousarray(template[top:bottom, left:right]),
                               cv2.TM_CCOEFF_NORMED, mask=mask)
    scores = np.nan_to_num(scores, nan=-1.0, posinf=-1.0, neginf=-1.0)
    _, _, _, (bx, by) = cv2.minMaxLoc(scores)
    return int(bx) - reach_px, int(by) - reach_px


def detail_ncc(ref: Reference, frame_bgr: npt.NDArray[np.uint8], hom: FloatArray) -> float:
    """:func:`appearance_ncc` of the detail only: both sides less their Gaussian blur
    (sigma a tenth of the outline's short side, at least 1.5 px).  A homography fitted to
    plain ground can make a photograph's broad light and dark areas correlate with the
    ground's shading (0.78 measured on bare pavement); the photograph's fine texture does
    not follow."""
    ov = overlay(ref, frame_bgr, hom)
    return 0.0 if ov is None else _ncc(_detail(ov))


def part_nccs(ref: Reference, frame_bgr: npt.NDArray[np.uint8], hom: FloatArray
              ) -> tuple[float, list[float]]:
    """:func:`detail_ncc`, and the same over each quarter of the plate that has detail of
    its own (its template's detail at least :data:`PART_DETAIL_SHARE` of the whole's, in
    standard deviation): an outline that hangs off its plate on one side, placed by a
    look-alike's features on the part the two photographs share, matches there and not
    over the ground beside it.  (0, []) when nothing is in view."""
    ov = overlay(ref, frame_bgr, hom, parts=True)
    if ov is None or ov.parts is None:
        return 0.0, []
    det = _detail(ov)
    whole = float(np.std(det.template[det.mask]))
    out = []
    for q in range(4):
        m = det.mask & (ov.parts == q)
        if int(m.sum()) < MIN_PIXELS // 4:
            continue
        if float(np.std(det.template[m])) < PART_DETAIL_SHARE * whole:
            continue  # a plain quarter: nothing to tell plate from ground
        out.append(_ncc(Overlay(det.template, det.frame, m, det.origin)))
    return _ncc(det), out


def _detail_sigma(mask: npt.NDArray[np.bool_]) -> float:
    """The detail's blur: a tenth of the outline's short side, at least 1.5 px."""
    short = min(np.ptp(np.nonzero(mask)[0]), np.ptp(np.nonzero(mask)[1])) + 1
    return max(1.5, 0.1 * float(short))


def _detail(ov: Overlay) -> Overlay:
    sigma = _detail_sigma(ov.mask)
    t = ov.template - cv2.GaussianBlur(ov.template, (0, 0), sigma)
    f = ov.frame - cv2.GaussianBlur(ov.frame, (0, 0), sigma)
    return Overlay(t, f, ov.mask, ov.origin, ov.parts)


def _ncc(ov: Overlay) -> float:
    a = ov.template[ov.mask].astype(np.float64)
    b = ov.frame[ov.mask].astype(np.float64)
    a -= a.mean()
    b -= b.mean()
    # elementwise sums, not BLAS dot products: BLAS threads stall on a busy machine
    den = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
    return float(np.sum(a * b) / den) if den > 1e-9 else 0.0


def _lag1(r: FloatArray, mask: npt.NDArray[np.bool_], axis: int) -> float:
    """Lag-one autocorrelation of the residual along ``axis`` over pairs inside the mask."""
    a = np.moveaxis(r, axis, 0)
    m = np.moveaxis(mask, axis, 0)
    both = m[1:] & m[:-1]
    x, y = a[1:][both], a[:-1][both]
    if len(x) < 8:
        return 0.0
    den = float(np.sqrt(np.sum(x * x) * np.sum(y * y)))
    return float(np.clip(np.sum(x * y) / den, 0.0, 0.95)) if den > 0 else 0.0


def fit_corner_sigma(ref: Reference, frame_bgr: npt.NDArray[np.uint8], hom: FloatArray
                     ) -> float | None:
    """RMS 1-sigma (px) of the eight corner coordinates from the fit (module notes);
    None when the plate is too small or has no gradient to fit."""
    ov = overlay(ref, frame_bgr, hom)
    return None if ov is None else _fit_sigma(ref, hom, ov)


def _fit_sigma(ref: Reference, hom: FloatArray, ov: Overlay) -> float | None:
    mask = ov.mask
    t, f = ov.template[mask].astype(np.float64), ov.frame[mask].astype(np.float64)
    tc = t - t.mean()
    gain = float(np.sum(tc * (f - f.mean())) / max(float(np.sum(tc * tc)), 1e-9))
    resid = np.zeros(mask.shape)
    resid[mask] = (f - f.mean()) - gain * tc  # after the best gain and offset
    s2 = float(np.mean(resid[mask] ** 2))
    inflation = 1.0
    for axis in (0, 1):
        rho = _lag1(resid, mask, axis)
        inflation *= (1.0 + rho) / (1.0 - rho)
    ys, xs = np.nonzero(mask)
    step = max(1, len(xs) // MAX_JACOBIAN_PIXELS)  # every step-th pixel, information x step
    ys, xs = ys[::step], xs[::step]
    gx = cv2.Sobel(ov.frame, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)[ys, xs]
    gy = cv2.Sobel(ov.frame, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)[ys, xs]
    pts = np.column_stack([xs + ov.origin[0], ys + ov.origin[1]]).astype(np.float64)
    jac = _pixel_motion(ref, hom, pts)  # (n, 8, 2): how each pixel moves per corner px
    j = jac[:, :, 0] * gx[:, None] + jac[:, :, 1] * gy[:, None]
    info = np.einsum("ik,il->kl", j, j) * step
    try:
        cov = np.linalg.inv(info) * s2 * min(inflation, MAX_INFLATION)
    except np.linalg.LinAlgError:
        return None
    var = float(np.trace(cov)) / 8.0
    return float(np.sqrt(var)) if np.isfinite(var) and var > 0 else None


def _pixel_motion(ref: Reference, hom: FloatArray, pts: FloatArray) -> FloatArray:
    """d(frame position of the reference point under each pixel) / d(corner coordinate)."""
    corners = project_corners(ref, hom)
    src = cv2.perspectiveTransform(pts.reshape(-1, 1, 2), np.linalg.inv(hom))
    out = np.empty((len(pts), 8, 2))
    for k in range(8):
        moved = corners.copy()
        moved.flat[k] += STEP_PX
        new = cv2.perspectiveTransform(src, homography_to(ref, moved)).reshape(-1, 2)
        out[:, k, :] = (new - pts) / STEP_PX
    return out


def quad_iou(a: FloatArray, b: FloatArray) -> float:
    """Intersection over union of two convex quadrilaterals (4x2, either winding)."""
    pa, pb = (cv2.convexHull(np.asarray(q, np.float32).reshape(-1, 1, 2)) for q in (a, b))
    area_a, area_b = float(cv2.contourArea(pa)), float(cv2.contourArea(pb))
    if area_a <= 0 or area_b <= 0:
        return 0.0
    inter, _ = cv2.intersectConvexConvex(pa, pb)
    return float(inter) / (area_a + area_b - float(inter))
