"""Acquisition by appearance reference: find a known landmark's photo in a frame.

A user's own landmarks -- photos of their signs and posters -- work without training a
network: ORB keypoints of each reference image are matched to the frame (ratio test),
a homography is fitted with RANSAC, and the match is kept only when the homography is
verified: enough inliers, a convex quadrilateral of plausible size and shape.  The
projected reference corners are the landmark's four image corners (top-left, top-right,
bottom-right, bottom-left), ready for the pose solver; the bounding box starts a tracker.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any, Literal

import cv2
import numpy as np
import numpy.typing as npt

from tracker.boxes import aspect_change, in_view_share, outline_box
from tracker.plate_light import channel_ratio, clipped, unclipped
from tracker.validation import check_image

FloatArray = npt.NDArray[np.float64]
#: A reference whose grey levels spread less than this is blank: nothing to align.
MIN_REFERENCE_STD = 2.0
#: Sizes (relative to the largest) at which a reference's keypoints are computed.
REFERENCE_SCALES = (1.0, 0.55, 0.3)
MIN_REFERENCE_SIDE_PX = 24


@dataclass(frozen=True)
class AcquireConfig:
    """Matching and verification thresholds.

    ``features``: ``sift`` (default) keeps matching real photographs under rotation, a
    scale change of 2-4x, light and JPEG, where ORB found no plate of issue 25's
    real-imagery world; ``orb`` is faster (binary descriptors).
    """

    features: Literal["sift", "orb"] = "sift"
    #: SIFT's contrast threshold (OpenCV's default 0.04 finds half as many keypoints on
    #: plates in 55 % light; 0.02 found 67 of 142 plates in view, 0.04 44, none wrong)
    sift_contrast_threshold: float = field(default=0.02, metadata={"gt": 0})
    max_features: int = field(default=1500, metadata={"ge": 100})
    reference_max_side_px: int = field(default=320, metadata={"ge": 32})
    ratio: float = field(default=0.8, metadata={"gt": 0, "lt": 1})
    min_inliers: int = field(default=12, metadata={"ge": 4})
    min_inlier_ratio: float = field(default=0.3, metadata={"gt": 0, "le": 1})
    ransac_px: float = field(default=4.0, metadata={"gt": 0})
    min_side_px: float = field(default=8.0, metadata={"gt": 0})
    max_aspect_change: float = field(default=4.0, metadata={"ge": 1})
    min_inlier_spread: float = field(default=0.1, metadata={"gt": 0, "le": 1})
    refine_ecc: bool = True
    ecc_iterations: int = field(default=40, metadata={"ge": 1})
    ecc_fine_iterations: int = field(default=10, metadata={"ge": 0})
    #: ``find(cut=True)``: a plate cut by the image's edge whose inliers are too few or too
    #: bunched for a homography is matched by a similarity (4 parameters) and aligned by
    #: ECC from there; it needs this many of the similarity's inliers (issue 19; not tuned:
    #: the code's ``min_inliers``, kept when a layer lowers that for whole plates).
    min_cut_inliers: int = field(default=12, metadata={"ge": 3})


@dataclass(frozen=True)
class Reference:
    """One landmark's appearance reference, prepared for matching."""

    landmark_id: str
    size_px: tuple[int, int]
    keypoints_px: npt.NDArray[np.float32]
    descriptors: npt.NDArray[Any]
    gray: npt.NDArray[np.float32]
    matchable: bool = True
    colour: npt.NDArray[np.uint8] = field(default_factory=lambda: np.zeros((1, 1, 3), np.uint8))
    #: ``colour`` projected on colour features (see :func:`reference_plane`), made on demand
    planes: dict[tuple[float, float, float], npt.NDArray[np.float32]] = field(
        default_factory=dict, compare=False, repr=False)
    #: a plane resized to a size in the frame (see :func:`reference_template`), kept
    templates: dict[tuple[tuple[float, float, float] | None, tuple[int, int]],
                    npt.NDArray[np.float32]] = field(default_factory=dict, compare=False,
                                                     repr=False)
    #: a colour feature mixed with grey levels (see :func:`mixed_weights`), made on demand
    mixes: dict[tuple[tuple[float, float, float], float], tuple[float, float, float]] = field(
        default_factory=dict, compare=False, repr=False)
    #: share of the appearance image's pixels with a channel at ``WHITE_LEVEL`` or more: the
    #: plate's own white, which a frame shows saturated without any over-exposure
    white_share: float = 0.0
    #: the appearance image's mean B, G, R (:func:`cast_gains`; None: computed when asked)
    channel_means: tuple[float, float, float] | None = None
    #: its luma's gradient energy over its chroma's (:func:`luma_chroma_ratio`): a
    #: photograph's is high, a coloured sign's low
    luma_over_chroma: float = 0.0


Weights = tuple[float, float, float]
#: Resized planes kept per reference (:func:`reference_template`): a tracked plate keeps
#: its size in the frame, to the pixel, for most frames (88 % on the survey), and a few
#: sizes cover a plate growing or shrinking by a pixel back and forth.
TEMPLATES_KEPT = 6
#: A reference pixel with a channel at this level or more is the plate's own white
#: (:attr:`Reference.white_share`).
WHITE_LEVEL = 250
_templates_lock = threading.Lock()  # the frame's threads and the lane share references


def reference_plane(ref: Reference, weights_bgr: Weights | None) -> npt.NDArray[np.float32]:
    """The reference as one float plane: grey levels, or ``colour @ weights_bgr`` (kept)."""
    if weights_bgr is None:
        return ref.gray
    plane = ref.planes.get(weights_bgr)
    if plane is None:  # two threads may both make it: the same values, no harm
        plane = project(ref.colour, weights_bgr)
        ref.planes[weights_bgr] = plane
    return plane


def reference_template(ref: Reference, weights_bgr: Weights | None, size: tuple[int, int]
                       ) -> npt.NDArray[np.float32]:
    """The reference's plane (:func:`reference_plane`) resized to ``size`` (w, h) by area
    averaging, float32, read-only; the last ``TEMPLATES_KEPT`` sizes of each plane are kept
    (issue 23: resizing the 256 px reference every frame cost more than the crop it is
    aligned on)."""
    key = (weights_bgr, size)
    template = ref.templates.get(key)
    if template is None:
        template = np.asarray(cv2.resize(reference_plane(ref, weights_bgr), size,
                                         interpolation=cv2.INTER_AREA), np.float32)
        template.flags.writeable = False
        with _templates_lock:  # per plane: a running track aligns two (refine_ecc)
            same = [k for k in ref.templates if k[0] == weights_bgr]
            if len(same) >= TEMPLATES_KEPT:
                del ref.templates[same[0]]  # the plane's oldest
            ref.templates[key] = template
    return template


#: B, G and R alone as weights (the appearance image's channels as planes).
CHANNEL_WEIGHTS: tuple[Weights, Weights, Weights] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0),
                                                     (0.0, 0.0, 1.0))
#: OpenCV's grey levels of BGR (``cv2.COLOR_BGR2GRAY``) as weights.
GREY_WEIGHTS: Weights = (0.114, 0.587, 0.299)


def mixed_weights(ref: Reference, weights_bgr: Weights, grey_share: float) -> Weights:
    """A plane ``grey_share`` grey levels and the rest ``weights_bgr``'s colour feature, each
    scaled to unit spread on the reference, grey's sign taken so that the two add up where
    they agree (kept per reference).

    A colour feature is mostly chroma, and a camera's frames keep chroma at half
    resolution (YUV 4:2:0, JPEG): an edge on the feature alone is blurred over two pixels.
    Grey levels keep the luma's full resolution, the feature the contrast that grey
    levels may lack; the mix aligns on both (docs/pose.md, "The fine stage's plane")."""
    key = (weights_bgr, grey_share)
    mixed = ref.mixes.get(key)
    if mixed is None:  # two threads may both make it: the same values, no harm
        feature, grey = reference_plane(ref, weights_bgr), ref.gray
        spread_f, spread_g = max(float(np.std(feature)), 1e-3), max(float(np.std(grey)), 1e-3)
        agree = float(np.mean((feature - feature.mean()) * (grey - grey.mean())))
        sign = 1.0 if agree >= 0 else -1.0
        v = ((1.0 - grey_share) * np.asarray(weights_bgr) / spread_f
             + grey_share * sign * np.asarray(GREY_WEIGHTS) / spread_g)
        v = v / max(float(np.abs(v).sum()), 1e-12)
        mixed = (float(v[0]), float(v[1]), float(v[2]))
        ref.mixes[key] = mixed
    return mixed


#: :func:`luma_chroma_ratio` looks at an image resized to about this long side (px) ...
RATIO_SIDE_PX = 80
#: ... with this share of each side left out (the plate's border and what a crop caught
#: beyond it).
RATIO_BORDER = 0.08
#: The ratio of an image without chroma contrast (a crop of grey video).
NO_CHROMA_RATIO = 1e6


def luma_chroma_ratio(image_bgr: npt.NDArray[np.uint8]) -> float:
    """The gradient energy of an image's luma (Y) over that of its chroma (Cr + Cb).

    A camera keeps chroma at half resolution and quantises it coarser (YUV 4:2:0, JPEG),
    so in a frame a plate's chroma edges are the least certain part of it.  A photograph
    of a wall or of the ground has little colour: 4.47 to 129 (39 % none at all) on the
    336 crops of 56 real-imagery worlds; the rendered signs 0.47-2.04 (docs/decisions.md,
    "Grey levels alone on a plate with little colour")."""
    h, w = image_bgr.shape[:2]
    scale = min(1.0, RATIO_SIDE_PX / max(h, w))
    small = image_bgr if scale >= 1.0 else cv2.resize(
        image_bgr, (max(3, round(w * scale)), max(3, round(h * scale))),
        interpolation=cv2.INTER_AREA)
    sh, sw = small.shape[:2]
    by, bx = int(RATIO_BORDER * sh), int(RATIO_BORDER * sw)
    ycc = cv2.cvtColor(small, cv2.COLOR_BGR2YCrCb).astype(np.float32)[by:sh - by, bx:sw - bx]
    energy = []
    for c in range(3):
        gx = cv2.Sobel(ycc[:, :, c], cv2.CV_32F, 1, 0, ksize=3)
        gy = cv2.Sobel(ycc[:, :, c], cv2.CV_32F, 0, 1, ksize=3)
        energy.append(float(np.sum(gx * gx + gy * gy)))
    chroma = energy[1] + energy[2]
    return NO_CHROMA_RATIO if chroma <= energy[0] / NO_CHROMA_RATIO else energy[0] / chroma


def project(image_bgr: npt.NDArray[np.uint8], weights_bgr: Weights) -> npt.NDArray[np.float32]:
    """``w_b B + w_g G + w_r R`` per pixel, float32."""
    return np.asarray(cv2.transform(image_bgr.astype(np.float32),
                                    np.asarray([weights_bgr], np.float32)), np.float32)


@dataclass(frozen=True)
class Match:
    """A verified sighting: corners TL, TR, BR, BL in the frame, and the box around them."""

    landmark_id: str
    corners_px: FloatArray
    box: tuple[float, float, float, float]
    inliers: int
    inlier_ratio: float
    homography: FloatArray


class ReferenceMatcher:
    """Holds the references of the landmarks to look for; ``find`` searches one frame."""

    def __init__(self, config: AcquireConfig | None = None) -> None:
        self.config = config or AcquireConfig()
        if self.config.features == "sift":
            self._features: cv2.Feature2D = cv2.SIFT.create(
                nfeatures=self.config.max_features,
                contrastThreshold=self.config.sift_contrast_threshold)
            self._matcher = cv2.BFMatcher(cv2.NORM_L2)
        else:
            self._features = cv2.ORB.create(nfeatures=self.config.max_features, fastThreshold=10)
            self._matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
        self.references: dict[str, Reference] = {}

    def sibling(self) -> ReferenceMatcher:
        """A matcher with the same references but its own ORB and matcher objects, for use
        on another thread (OpenCV's feature objects are not meant to be shared)."""
        twin = ReferenceMatcher(self.config)
        twin.references = self.references
        return twin

    def add(self, landmark_id: str, image_bgr: npt.NDArray[np.uint8]) -> Reference:
        """Prepare a reference image.

        A plain plate with few keypoints is kept for alignment (``matchable`` False: it is
        found by prediction from a fix, not by feature matching); an image with no
        texture at all is refused with ValueError.
        """
        check_image(image_bgr, "image_bgr")
        gray = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
        if float(gray.std()) < MIN_REFERENCE_STD:
            raise ValueError(f"image_bgr: the reference of {landmark_id!r} is blank (grey "
                             f"level spread {gray.std():.1f}); expected some texture to align")
        h, w = image_bgr.shape[:2]
        top = min(1.0, self.config.reference_max_side_px / max(h, w))
        pts_all, desc_all = [], []
        # several sizes: ORB's own pyramid spans about 4x, a landmark far away is smaller
        # (SIFT's scale space covers that by itself)
        scales = REFERENCE_SCALES if self.config.features == "orb" else (1.0,)
        for scale in (top * f for f in scales):
            size = (max(1, round(w * scale)), max(1, round(h * scale)))
            if min(size) < MIN_REFERENCE_SIDE_PX:
                break
            small = cv2.resize(image_bgr, size, interpolation=cv2.INTER_AREA)
            grey = cv2.cvtColor(small, cv2.COLOR_BGR2GRAY)
            kps, desc = self._features.detectAndCompute(grey, None)
            if desc is not None and len(kps):
                # a keypoint at k in the resized image is at (k + 0.5) / scale - 0.5 in ref
                pts = (np.array([kp.pt for kp in kps], np.float32) + 0.5) / np.float32(scale)
                pts_all.append(pts - np.float32(0.5))
                desc_all.append(np.asarray(desc))
        pts = np.concatenate(pts_all) if pts_all else np.zeros((0, 2), np.float32)
        descriptors = np.concatenate(desc_all) if desc_all else np.zeros((0, 32), np.uint8)
        matchable = len(pts) >= self.config.min_inliers
        white = float(np.mean(np.max(image_bgr, axis=2) >= WHITE_LEVEL))
        b_mean, g_mean, r_mean = cv2.mean(image_bgr)[:3]
        ref = Reference(landmark_id, (w, h), pts, descriptors, gray, matchable,
                        np.ascontiguousarray(image_bgr), white_share=white,
                        channel_means=(b_mean, g_mean, r_mean),
                        luma_over_chroma=luma_chroma_ratio(image_bgr))
        self.references[landmark_id] = ref
        return ref

    def find(self, image_bgr: npt.NDArray[np.uint8], landmark_ids: list[str] | None = None,
             roi: tuple[float, float, float, float] | None = None, cut: bool = False
             ) -> list[Match]:
        """Verified matches of the given references (all when None), best first.

        ``roi`` (x, y, w, h) limits the search to that part of the frame (cheaper; used to
        recover a tracked landmark's corners); results are in frame coordinates.  With
        ``cut``, a plate cut by the image's edge is also found from the matches on its part
        in view (:meth:`_match_cut`).
        """
        check_image(image_bgr, "image_bgr")
        x0, y0 = 0, 0
        view = image_bgr
        if roi is not None:
            height, width = image_bgr.shape[:2]
            x0, y0 = max(0, int(roi[0])), max(0, int(roi[1]))
            x1 = min(width, int(np.ceil(roi[0] + roi[2])))
            y1 = min(height, int(np.ceil(roi[1] + roi[3])))
            if x1 - x0 < 16 or y1 - y0 < 16:
                return []
            view = image_bgr[y0:y1, x0:x1]
        gray = np.asarray(cv2.cvtColor(view, cv2.COLOR_BGR2GRAY), np.uint8)
        kps, desc = self._features.detectAndCompute(gray, None)
        if desc is None or len(kps) < self.config.min_inliers:
            return []
        frame_pts = np.array([kp.pt for kp in kps], np.float32) + np.array([x0, y0], np.float32)
        frame_gray = np.asarray(cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY), np.uint8)
        ids = self.references if landmark_ids is None else landmark_ids
        frame_desc = np.asarray(desc)
        found = [self._match_one(self.references[i], frame_pts, frame_desc, frame_gray, cut)
                 for i in ids if i in self.references and self.references[i].matchable]
        return sorted((m for m in found if m is not None), key=lambda m: -m.inliers)

    def _match_one(self, ref: Reference, frame_pts: npt.NDArray[np.float32],
                   frame_desc: npt.NDArray[Any], frame_gray: npt.NDArray[np.uint8],
                   cut: bool = False) -> Match | None:
        cfg = self.config
        pairs = self._matcher.knnMatch(ref.descriptors, frame_desc, k=2)
        good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < cfg.ratio * p[1].distance]
        src = ref.keypoints_px[[m.queryIdx for m in good]]
        dst = frame_pts[[m.trainIdx for m in good]]
        whole = self._match_whole(ref, src, dst, frame_gray) \
            if len(good) >= cfg.min_inliers else None
        if whole is not None or not cut or len(good) < cfg.min_cut_inliers:
            return whole
        return self._match_cut(ref, src, dst, frame_gray)

    def _match_cut(self, ref: Reference, src: npt.NDArray[np.float32],
                   dst: npt.NDArray[np.float32], frame_gray: npt.NDArray[np.uint8]
                   ) -> Match | None:
        """A plate cut by the image's edge from the matches ``src`` (reference px) ->
        ``dst`` (frame px) on its part in view: a similarity by RANSAC (its inliers bunch
        on that part, where a homography's extrapolated corners go hundreds of pixels
        astray: measured on the square's wall-01 entering at 31-42 % in view), then the
        homography by ECC from there (:func:`refine_ecc`, held to its correlation); None
        when too few inliers agree, ECC fails, the plate is not cut by the edge or its
        outline is implausible.  Whether it is the plate is then the caller's to verify
        (its warped appearance on the part in view)."""
        cfg = self.config
        rough, mask = cv2.estimateAffinePartial2D(src, dst, method=cv2.RANSAC,
                                                  ransacReprojThreshold=cfg.ransac_px)
        if rough is None or mask is None:
            return None
        inliers = int(mask.sum())
        if inliers < cfg.min_cut_inliers or inliers / len(src) < cfg.min_inlier_ratio:
            return None
        hom = refine_ecc(ref, frame_gray, np.vstack([rough, (0.0, 0.0, 1.0)]),
                         cfg.ecc_iterations, fine_iterations=cfg.ecc_fine_iterations)
        if hom is None:
            return None
        corners = project_corners(ref, hom)
        height, width = frame_gray.shape[:2]
        if in_view_share(corners, width, height) >= 1.0 or \
                not plausible_quad(corners, ref.size_px, cfg):
            return None  # a whole plate is the homography's to find
        return _match_of(ref, corners, inliers, inliers / len(src), hom)

    def _match_whole(self, ref: Reference, src: npt.NDArray[np.float32],
                     dst: npt.NDArray[np.float32], frame_gray: npt.NDArray[np.uint8]
                     ) -> Match | None:
        """A plate from the matches ``src`` -> ``dst`` by a homography (RANSAC), its
        inliers spread over the reference, refined by ECC."""
        cfg = self.config
        rough, mask = cv2.findHomography(src, dst, cv2.RANSAC, cfg.ransac_px)
        if rough is None or mask is None:
            return None
        inliers = int(mask.sum())
        if inliers < cfg.min_inliers or inliers / len(src) < cfg.min_inlier_ratio:
            return None
        w, h = ref.size_px
        # inliers bunched in one corner extrapolate the corners badly: ask for spread
        hull = cv2.convexHull(src[mask.ravel() > 0].reshape(-1, 1, 2))
        if cv2.contourArea(hull) < cfg.min_inlier_spread * w * h:
            return None
        keep = mask.ravel() > 0
        refined, _ = cv2.findHomography(src[keep], dst[keep], 0)  # least squares on inliers
        hom = np.asarray(refined if refined is not None else rough, np.float64)
        if cfg.refine_ecc:
            aligned = refine_ecc(ref, frame_gray, hom, cfg.ecc_iterations,
                                 fine_iterations=cfg.ecc_fine_iterations)
            hom = hom if aligned is None else aligned
        corners = project_corners(ref, hom)
        if not plausible_quad(corners, (w, h), cfg):
            return None
        return _match_of(ref, corners, inliers, inliers / len(src), hom)


def _match_of(ref: Reference, corners: FloatArray, inliers: int, ratio: float,
              hom: FloatArray) -> Match:
    """The :class:`Match` of ``ref`` at ``corners`` (the box around them)."""
    return Match(ref.landmark_id, corners, outline_box(corners), inliers, ratio,
                 np.asarray(hom, np.float64))


def search_template(ref: Reference, frame_bgr: npt.NDArray[np.uint8],
                    widths_px: tuple[float, ...], downscale: float = 0.5
                    ) -> tuple[float, FloatArray] | None:
    """Best normalised cross-correlation of the reference over the frame at a few sizes.

    For references with too few keypoints to match (plain plates, simple graphics) and
    for small, distant landmarks.  Returns (score, homography reference -> frame) of the
    best fronto-parallel placement; :func:`refine_ecc` then fits the perspective.
    """
    small = cv2.resize(frame_bgr, None, fx=downscale, fy=downscale,
                       interpolation=cv2.INTER_AREA).astype(np.float32)
    w, h = ref.size_px
    best: tuple[float, FloatArray] | None = None
    for width in widths_px:
        tw = max(6, round(width * downscale))
        th = max(6, round(tw * h / w))
        if tw >= small.shape[1] or th >= small.shape[0]:
            continue
        template = cv2.resize(ref.colour, (tw, th), interpolation=cv2.INTER_AREA)
        scores = cv2.matchTemplate(small, template.astype(np.float32), cv2.TM_CCOEFF_NORMED)
        _, score, _, (x, y) = cv2.minMaxLoc(scores)
        if best is None or score > best[0]:
            sx = tw / downscale / w
            sy = th / downscale / h
            hom = np.array([[sx, 0.0, x / downscale], [0.0, sy, y / downscale], [0, 0, 1.0]])
            best = (float(score), hom)
    return best


def reference_quad(ref: Reference) -> FloatArray:
    """The reference image's outer corners TL, TR, BR, BL in its pixel coordinates.

    OpenCV puts pixel *centres* on integer coordinates, so an image of ``w`` pixels spans
    -0.5 .. w - 0.5.  Taking 0 .. w instead shifts every corner by half a reference pixel
    (measured: the aligned corners of the simulated world's plates were ~0.5 px off).
    """
    w, h = ref.size_px
    return np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]],
                    np.float64)


def project_corners(ref: Reference, hom: FloatArray) -> FloatArray:
    """The reference's corners TL, TR, BR, BL through homography ``hom`` (4x2)."""
    quad = reference_quad(ref).reshape(-1, 1, 2)
    return np.asarray(cv2.perspectiveTransform(quad, hom).reshape(4, 2), np.float64)


def homography_to(ref: Reference, corners_px: FloatArray) -> FloatArray:
    """The homography taking the reference's corners to ``corners_px`` (TL, TR, BR, BL)."""
    src = reference_quad(ref).astype(np.float32)
    return np.asarray(cv2.getPerspectiveTransform(src, corners_px.astype(np.float32)),
                      np.float64)



def outline_window(corners: FloatArray, width: int, height: int, margin: float, least: int
                   ) -> tuple[int, int, int, int] | None:
    """``(x0, y0, x1, y1)``: the frame region around an outline, ``margin`` px wider on
    every side and clipped to the frame; None when narrower or lower than ``least`` px."""
    x0, y0 = (int(v) for v in np.floor(np.maximum(corners.min(axis=0) - margin, 0.0)))
    x1 = int(min(np.ceil(corners[:, 0].max() + margin), width))
    y1 = int(min(np.ceil(corners[:, 1].max() + margin), height))
    if x1 - x0 < least or y1 - y0 < least:
        return None
    return x0, y0, x1, y1


def size_in_frame(ref: Reference, corners: FloatArray, least: int) -> tuple[int, int]:
    """The reference's size (w, h) scaled to about the area of its outline in the frame
    (never up, never below ``least`` px)."""
    w, h = ref.size_px
    area = float(cv2.contourArea(corners.astype(np.float32)))
    scale = float(np.clip(np.sqrt(max(area, 1.0) / (w * h)), 0.05, 1.0))
    return max(least, round(w * scale)), max(least, round(h * scale))


#: The unsmoothed stage leaves out the template's outer ring (``refine_ecc``'s
#: ``edge_band_px``) when its short side is at least this long: every template (the
#: default of ``perception.ecc_band_from_px``).  Until 2026-12-05 it was 48, a small
#: plate keeping its ring; the ring's samples mix in the ground and pulled small real
#: plates' outlines inwards (docs/decisions.md, "A small plate's ring is left out too").
BAND_FROM_PX = 1

#: The coarse ECC stage runs at half resolution when the template's short side is at
#: least this long (so that the halved one still has some 24 px to align).
HALVE_FROM_PX = 48


def refine_ecc(ref: Reference, frame: npt.NDArray[np.uint8], hom: FloatArray,
               iterations: int = 40, min_correlation: float = 0.6,
               fine_iterations: int = 10, weights_bgr: Weights | None = None,
               edge_band_px: int = 0, fine_grey_share: float = 0.0,
               band_from_px: int = BAND_FROM_PX, clipped_out: bool = True
               ) -> FloatArray | None:
    """Sub-pixel homography (reference -> frame) by ECC alignment, from an estimate.

    Keypoints from ORB's coarser pyramid levels are off by a pixel or more, and the
    corners extrapolate that; aligning the reference's pixels themselves removes it.  Only
    the region around the predicted quadrilateral is aligned, against the reference
    scaled to about its size in the frame, so the cost follows the landmark's size, not
    the frame's.  None when ECC fails or the correlation stays under ``min_correlation``.

    Two stages: ``iterations`` on Gaussian-smoothed images at half resolution (OpenCV's
    5x5 smoothing: a wide basin, cheap; but at the plate's edges the smoothed frame mixes
    in the background while the smoothed template does not, which pulls an edge by up to
    ~1 px), then ``fine_iterations`` unsmoothed at full resolution from there (exact, but
    only from close by).  On the simulated world's plates this took the corner error from
    0.45 to 0.13 px RMS (docs/pose.md, "Corner accuracy").

    ``frame`` is grey (H, W) or BGR (H, W, 3), aligned with the reference's grey levels;
    with ``weights_bgr`` it is BGR and aligned on that colour feature of both (the
    tracker's best feature separates the plate from what surrounds it, where grey levels
    may not: an edge without grey contrast cannot hold a corner).  ``fine_grey_share``:
    the unsmoothed stage aligns on the feature mixed with that share of grey levels
    (:func:`mixed_weights`; the same window and template size, so the warp carries over).
    ``band_from_px``: the ring is left out only of a template whose short side is at least
    this long.  ``clipped_out``: the unsmoothed stage leaves out the template's pixels that
    the plate's light took past what the frame holds (:func:`unclipped_part`).
    """
    start = ecc_start(ref, frame, hom, weights_bgr)
    if start is None:
        return None
    template, roi, warp = start.template, start.roi, start.warp
    try:
        cc, warp = _ecc_coarse(template, roi, warp, iterations)
        if fine_iterations > 0:
            if weights_bgr is not None and fine_grey_share > 0.0:
                template, roi = on_plane(start, ref, frame, mixed_weights(
                    ref, weights_bgr, fine_grey_share))
            keep = unclipped_part(start, ref, frame, warp) if clipped_out else None
            cc, warp = _ecc(template, roi, warp, fine_iterations, 1e-5, 1, edge_band_px,
                            band_from_px, keep)
    except cv2.error:
        return None
    out = start.from_roi @ warp @ start.to_template
    if cc < min_correlation or not np.all(np.isfinite(out)):
        return None
    return np.asarray(out / out[2, 2], np.float64)


@dataclass(frozen=True)
class EccStart:
    """What an ECC alignment of a reference in a frame starts from (:func:`ecc_start`)."""

    #: the reference's plane at its size in the frame (float32)
    template: npt.NDArray[np.float32]
    #: the frame's window around the outline: grey, or the colour feature (float32)
    roi: npt.NDArray[np.float32]
    #: reference px -> template px
    to_template: FloatArray
    #: window px -> frame px
    from_roi: FloatArray
    #: template px -> window px, from the homography the alignment starts at
    warp: FloatArray
    #: each channel's (B, G, R) gain of the plate in the frame over its reference
    #: (:func:`cast_gains`): the frame's colour planes are projected with the weights
    #: divided by them
    gains: FloatArray = field(default_factory=lambda: np.ones(3))


def ecc_start(ref: Reference, frame: npt.NDArray[np.uint8], hom: FloatArray,
              weights_bgr: Weights | None = None) -> EccStart | None:
    """The template, the window and the starting warp for aligning ``ref`` at ``hom``
    (reference -> frame) in ``frame`` (grey, or BGR: grey levels of the window only, or
    ``weights_bgr``'s colour feature); None when the outline is not finite or not in view.
    The window is the outline's box, 15 % of its size plus 6 px larger."""
    corners = project_corners(ref, hom)
    if not np.all(np.isfinite(corners)):
        return None
    height, width = frame.shape[:2]
    margin = 0.15 * float(np.ptp(corners, axis=0).max()) + 6.0
    window = outline_window(corners, width, height, margin, 8)
    if window is None:
        return None
    x0, y0, x1, y1 = window
    template = reference_template(ref, weights_bgr, size_in_frame(ref, corners, 8))
    s_ref = resize_map(ref.size_px, template.shape[1::-1])  # ref -> template
    t_roi = np.array([[1.0, 0.0, x0], [0.0, 1.0, y0], [0.0, 0.0, 1.0]])  # roi -> frame
    warp = np.linalg.inv(t_roi) @ hom @ np.linalg.inv(s_ref)  # template -> roi
    crop = frame[y0:y1, x0:x1]
    gains = np.ones(3)
    if weights_bgr is not None:
        gains = cast_gains(ref, crop, corners - (x0, y0))
        roi = project(crop, cast_weights(weights_bgr, gains))
    elif crop.ndim == 3:  # grey levels of the region only, not of the whole frame
        roi = np.asarray(cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY), np.float32)
    else:
        roi = crop.astype(np.float32)
    return EccStart(template, roi, s_ref, t_roi, warp, gains)


#: A plate whose channels' gains differ from their mean by less than this is under white
#: light: its colour plane is left as it is
CAST_FROM = 0.08


def own_means(ref: Reference) -> FloatArray:
    """The appearance image's mean B, G, R."""
    return np.asarray(ref.channel_means if ref.channel_means is not None
                      else cv2.mean(ref.colour)[:3], np.float64)


def unclipped_part(start: EccStart, ref: Reference, frame: npt.NDArray[np.uint8],
                   warp: FloatArray) -> npt.NDArray[np.uint8] | None:
    """:func:`tracker.plate_light.unclipped` of ``start``'s template in ``frame``, the
    outline where ``warp`` (template -> window) puts it."""
    x0, y0 = int(start.from_roi[0, 2]), int(start.from_roi[1, 2])
    height, width = start.roi.shape[:2]
    crop = frame[y0:y0 + height, x0:x0 + width]
    flat = clipped(crop)
    if flat is None:  # most windows: nothing more to do
        return None
    quad = project_corners(ref, start.from_roi @ warp @ start.to_template) - (x0, y0)
    size = start.template.shape[1::-1]
    channels = [reference_template(ref, w, size) for w in CHANNEL_WEIGHTS]
    return unclipped(crop, flat, quad, warp, channels, own_means(ref))


def cast_gains(ref: Reference, crop: npt.NDArray[np.uint8], quad: FloatArray) -> FloatArray:
    """Each channel's mean inside the outline ``quad`` (crop px) over the reference's, as a
    share of their average: 1, 1, 1 under white light whatever its level; a colour cast
    raises one channel against another, which no gain and offset of a colour plane such as
    R - B takes up."""
    ratio = channel_ratio(crop, quad, own_means(ref))
    if ratio is None:
        return np.ones(3)
    gains = ratio / ratio.mean()
    return gains if float(np.abs(gains - 1.0).max()) >= CAST_FROM else np.ones(3)


def cast_weights(weights_bgr: Weights, gains: FloatArray) -> Weights:
    """``weights_bgr`` for a frame whose channels carry ``gains``."""
    b, g, r = (float(w / k) for w, k in zip(weights_bgr, gains, strict=True))
    return b, g, r


def on_plane(start: EccStart, ref: Reference, frame: npt.NDArray[np.uint8],
             weights_bgr: Weights) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """The template and the window of ``start`` (:func:`ecc_start`, same outline, same
    sizes: its warps carry over) on ``weights_bgr``'s plane, without finding the window
    again (issue 23: the same values as a second :func:`ecc_start`)."""
    x0, y0 = int(start.from_roi[0, 2]), int(start.from_roi[1, 2])
    height, width = start.roi.shape[:2]
    template = reference_template(ref, weights_bgr, start.template.shape[1::-1])
    return template, project(frame[y0:y0 + height, x0:x0 + width],
                             cast_weights(weights_bgr, start.gains))


def resize_map(size: tuple[int, int], new_size: tuple[int, int]) -> FloatArray:
    """Pixel coordinates of an image of ``size`` (w, h) -> of it resized to ``new_size``;
    pixel centres sit on integers, so x' = (x + 0.5) s - 0.5."""
    sx, sy = new_size[0] / size[0], new_size[1] / size[1]
    return np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])


def _ecc_coarse(template: npt.NDArray[np.float32], roi: npt.NDArray[np.float32],
                warp: FloatArray, iterations: int) -> tuple[float, FloatArray]:
    """The smoothed stage, on both images halved when the template is large enough."""
    if min(template.shape) < HALVE_FROM_PX:
        return _ecc(template, roi, warp, iterations, 1e-4, 5)
    half_t = np.asarray(cv2.resize(template, None, fx=0.5, fy=0.5,
                                   interpolation=cv2.INTER_AREA), np.float32)
    half_r = np.asarray(cv2.resize(roi, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA),
                        np.float32)
    to_t = resize_map(template.shape[1::-1], half_t.shape[1::-1])
    to_r = resize_map(roi.shape[1::-1], half_r.shape[1::-1])
    cc, half = _ecc(half_t, half_r, to_r @ warp @ np.linalg.inv(to_t), iterations, 1e-4, 5)
    return cc, np.linalg.inv(to_r) @ half @ to_t


def _ecc(template: npt.NDArray[np.float32], roi: npt.NDArray[np.float32], warp: FloatArray,
         iterations: int, eps: float, blur: int, band: int = 0,
         band_from: int = BAND_FROM_PX, keep: npt.NDArray[np.uint8] | None = None
         ) -> tuple[float, FloatArray]:
    """One cv2.findTransformECC run (homography template -> roi); raises cv2.error.
    ``band``: the template's outer ``band`` px are left out when its short side is at least
    ``band_from`` px.  ``keep``: the template's pixels to align on (1; None: all)."""
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, eps)
    start = (warp / warp[2, 2]).astype(np.float32)
    banded = band > 0 and min(template.shape[:2]) >= band_from
    if banded or keep is not None:
        mask = np.ones(template.shape[:2], np.uint8) if keep is None else keep.copy()
        if banded:
            mask[:band], mask[-band:], mask[:, :band], mask[:, -band:] = 0, 0, 0, 0
        # no input mask (None), not an all-ones one: the same warp to the bit, measured
        # ~18 % less time (docs/benchmarks.md, "The follow-mode square's CPU")
        cc, found = cv2.findTransformECCWithMask(  # type: ignore[call-overload]
            template, roi, mask, None, start, cv2.MOTION_HOMOGRAPHY, criteria, blur)
        return float(cc), np.asarray(found, np.float64)
    # the stubs want a mask before gaussFiltSize; OpenCV takes None (no mask)
    cc, found = cv2.findTransformECC(  # type: ignore[call-overload]
        template, roi, start, cv2.MOTION_HOMOGRAPHY, criteria, None, blur)
    return float(cc), np.asarray(found, np.float64)


def plausible_quad(corners: FloatArray, ref_size: tuple[int, int], cfg: AcquireConfig) -> bool:
    """Convex, same winding as the reference, sides long enough, aspect not distorted."""
    if not np.all(np.isfinite(corners)):
        return False
    edges = np.roll(corners, -1, axis=0) - corners
    cross = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(
        edges, -1, axis=0)[:, 0]
    if not np.all(cross > 0):  # image y points down: a clockwise-drawn quad has cross > 0
        return False
    if np.linalg.norm(edges, axis=1).min() < cfg.min_side_px:
        return False
    return aspect_change(corners, ref_size) <= cfg.max_aspect_change
