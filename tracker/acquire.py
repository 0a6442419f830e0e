"""Acquisition by appearance reference: find a known landmark's photo in a frame.

A user's own landmarks -- photos of their signs and posters -- work without training a
network: ORB keypoints of each reference image are matched to the frame (ratio test),
a homography is fitted with RANSAC, and the match is kept only when the homography is
verified: enough inliers, a convex quadrilateral of plausible size and shape.  The
projected reference corners are the landmark's four image corners (top-left, top-right,
bottom-right, bottom-left), ready for the pose solver; the bounding box starts a tracker.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
import numpy.typing as npt

from tracker.validation import check_image

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class AcquireConfig:
    """Matching and verification thresholds."""

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


@dataclass(frozen=True)
class Reference:
    """One landmark's appearance reference, prepared for matching."""

    landmark_id: str
    size_px: tuple[int, int]
    keypoints_px: npt.NDArray[np.float32]
    descriptors: npt.NDArray[np.uint8]
    gray: npt.NDArray[np.float32]


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
        self._orb = cv2.ORB.create(nfeatures=self.config.max_features, fastThreshold=10)
        self._matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
        self.references: dict[str, Reference] = {}

    def add(self, landmark_id: str, image_bgr: npt.NDArray[np.uint8]) -> Reference:
        """Prepare a reference image; ValueError if it has too little texture to match."""
        check_image(image_bgr, "image_bgr")
        h, w = image_bgr.shape[:2]
        scale = min(1.0, self.config.reference_max_side_px / max(h, w))
        small = cv2.resize(image_bgr, (max(1, round(w * scale)), max(1, round(h * scale))),
                           interpolation=cv2.INTER_AREA) if scale < 1.0 else image_bgr
        kps, desc = self._orb.detectAndCompute(cv2.cvtColor(small, cv2.COLOR_BGR2GRAY), None)
        if desc is None or len(kps) < self.config.min_inliers:
            raise ValueError(f"image_bgr: the reference of {landmark_id!r} has "
                             f"{0 if desc is None else len(kps)} keypoints; expected at least "
                             f"{self.config.min_inliers} (too little texture to match)")
        pts = np.array([kp.pt for kp in kps], np.float32) / np.float32(scale)
        gray = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
        ref = Reference(landmark_id, (w, h), pts, np.asarray(desc, np.uint8), gray)
        self.references[landmark_id] = ref
        return ref

    def find(self, image_bgr: npt.NDArray[np.uint8],
             landmark_ids: list[str] | None = None) -> list[Match]:
        """Verified matches of the given references (all when None), best first."""
        check_image(image_bgr, "image_bgr")
        kps, desc = self._orb.detectAndCompute(cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY),
                                               None)
        if desc is None or len(kps) < self.config.min_inliers:
            return []
        frame_pts = np.array([kp.pt for kp in kps], np.float32)
        frame_gray = np.asarray(cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY), np.uint8)
        ids = self.references if landmark_ids is None else landmark_ids
        frame_desc = np.asarray(desc, np.uint8)
        found = [self._match_one(self.references[i], frame_pts, frame_desc, frame_gray)
                 for i in ids if i in self.references]
        return sorted((m for m in found if m is not None), key=lambda m: -m.inliers)

    def _match_one(self, ref: Reference, frame_pts: npt.NDArray[np.float32],
                   frame_desc: npt.NDArray[np.uint8],
                   frame_gray: npt.NDArray[np.uint8]) -> Match | None:
        cfg = self.config
        pairs = self._matcher.knnMatch(ref.descriptors, frame_desc, k=2)
        good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < cfg.ratio * p[1].distance]
        if len(good) < cfg.min_inliers:
            return None
        src = ref.keypoints_px[[m.queryIdx for m in good]]
        dst = frame_pts[[m.trainIdx for m in good]]
        rough, mask = cv2.findHomography(src, dst, cv2.RANSAC, cfg.ransac_px)
        if rough is None or mask is None:
            return None
        inliers = int(mask.sum())
        if inliers < cfg.min_inliers or inliers / len(good) < cfg.min_inlier_ratio:
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
            hom = refine_ecc(ref, frame_gray, hom, cfg.ecc_iterations)
        corners_ref = np.array([[0, 0], [w, 0], [w, h], [0, h]], np.float64).reshape(-1, 1, 2)
        corners = np.asarray(cv2.perspectiveTransform(corners_ref, hom).reshape(4, 2),
                             np.float64)
        if not plausible_quad(corners, (w, h), cfg):
            return None
        x0, y0 = corners.min(axis=0)
        x1, y1 = corners.max(axis=0)
        box = (float(x0), float(y0), float(x1 - x0), float(y1 - y0))
        return Match(ref.landmark_id, corners, box, inliers, inliers / len(good),
                     np.asarray(hom, np.float64))


def refine_ecc(ref: Reference, frame_gray: npt.NDArray[np.uint8], hom: FloatArray,
               iterations: int = 40) -> FloatArray:
    """Sub-pixel homography by ECC image alignment, started from the feature estimate.

    Keypoints from ORB's coarser pyramid levels are off by a pixel or more, and the
    corners extrapolate that; aligning the reference's pixels themselves removes it.  The
    feature estimate is kept when ECC does not converge.
    """
    warp = (hom / hom[2, 2]).astype(np.float32)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, 1e-5)
    try:
        _, warp = cv2.findTransformECC(ref.gray, frame_gray.astype(np.float32), warp,
                                       cv2.MOTION_HOMOGRAPHY, criteria)
    except cv2.error:
        return hom
    out = warp.astype(np.float64)
    return out if np.all(np.isfinite(out)) else hom


def plausible_quad(corners: FloatArray, ref_size: tuple[int, int], cfg: AcquireConfig) -> bool:
    """Convex, same winding as the reference, sides long enough, aspect not distorted."""
    if not np.all(np.isfinite(corners)):
        return False
    edges = np.roll(corners, -1, axis=0) - corners
    cross = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(
        edges, -1, axis=0)[:, 0]
    if not np.all(cross > 0):  # image y points down: a clockwise-drawn quad has cross > 0
        return False
    sides = np.linalg.norm(edges, axis=1)
    if sides.min() < cfg.min_side_px:
        return False
    aspect_ref = ref_size[0] / ref_size[1]
    aspect = (sides[0] + sides[2]) / max(sides[1] + sides[3], 1e-9)
    change = max(aspect / aspect_ref, aspect_ref / aspect)
    return bool(change <= cfg.max_aspect_change)
