"""Boxes and quadrilaterals in image pixels: overlap, clipping, corners, share in view.

Boxes are (x, y, w, h) with (x, y) the top-left corner; quadrilaterals are 4x2 corner
arrays TL, TR, BR, BL.  Pure numpy / OpenCV.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.geometry import FloatArray
from tracker.types import Box

#: An outline foreshortened along one of its plate's axes to less than this share of the
#: other (a plate seen more than ~81 deg off its normal) is not a plate in view: an
#: alignment run away onto a sliver, or a plate edge-on whose corners say nothing.
MIN_FORESHORTENING = 0.15


def box_overlap(a: Box, b: Box) -> float:
    """The area two (x, y, w, h) boxes share."""
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[0] + a[2], b[0] + b[2]), min(a[1] + a[3], b[1] + b[3])
    return max(0.0, x1 - x0) * max(0.0, y1 - y0)


def box_iou(a: Box, b: Box) -> float:
    """Intersection over union of two (x, y, w, h) boxes."""
    inter = box_overlap(a, b)
    union = a[2] * a[3] + b[2] * b[3] - inter
    return inter / union if union > 0 else 0.0


def box_cover(a: Box, b: Box) -> float:
    """The share of the smaller of two (x, y, w, h) boxes that lies in the other."""
    smaller = min(a[2] * a[3], b[2] * b[3])
    return box_overlap(a, b) / smaller if smaller > 0 else 0.0


def clip_box(box: Box, width: int, height: int) -> Box | None:
    """``box`` cut to the image; None when too little is left to track."""
    x0, y0 = max(0.0, box[0]), max(0.0, box[1])
    x1, y1 = min(float(width), box[0] + box[2]), min(float(height), box[1] + box[3])
    if x1 - x0 < 4 or y1 - y0 < 4:
        return None
    return (x0, y0, x1 - x0, y1 - y0)


def centre_on(corners: FloatArray, box: Box) -> bool:
    """Does ``box``'s centre lie on the quadrilateral ``corners`` (its edge included)?"""
    x, y, w, h = box
    outline = np.asarray(corners, np.float32).reshape(-1, 1, 2)
    return cv2.pointPolygonTest(outline, (x + w / 2, y + h / 2), False) >= 0


def outline_box(corners: FloatArray) -> Box:
    """The (x, y, w, h) box around a quadrilateral's corners."""
    x0, y0 = corners.min(axis=0)
    x1, y1 = corners.max(axis=0)
    return (float(x0), float(y0), float(x1 - x0), float(y1 - y0))


def aspect_change(corners: FloatArray, size: tuple[float, float]) -> float:
    """How far the outline ``corners`` (TL, TR, BR, BL) is from the aspect of its plate
    ``size`` = (width, height), any unit: the ratio of the two aspects, the larger over the
    smaller (1: the plate's own; a plate turned 60 deg off its normal about one axis: 2)."""
    sides = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
    aspect = (sides[0] + sides[2]) / max(float(sides[1] + sides[3]), 1e-9)
    ref = size[0] / size[1]
    return float(max(aspect / ref, ref / max(aspect, 1e-12)))


def squashed(corners: FloatArray, size: tuple[float, float]) -> bool:
    """Is the outline ``corners`` of a plate ``size`` foreshortened along one axis to under
    ``MIN_FORESHORTENING`` of the other (:func:`aspect_change`)?"""
    return aspect_change(corners, size) * MIN_FORESHORTENING > 1.0


def box_corners(box: Box) -> FloatArray:
    """The corners TL, TR, BR, BL of an (x, y, w, h) box."""
    x, y, w, h = box
    return np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]], np.float64)


def inside(corners: FloatArray, width: int, height: int, margin: float) -> bool:
    """All corners at least ``margin`` px inside the image."""
    return bool(np.all(corners >= margin) and np.all(corners[:, 0] <= width - margin)
                and np.all(corners[:, 1] <= height - margin))


def in_view_share(corners: FloatArray, width: int, height: int) -> float:
    """Share of the quadrilateral's area inside the image (0 for a degenerate quad)."""
    quad = np.asarray(corners, np.float32).reshape(-1, 1, 2)
    area = abs(float(cv2.contourArea(quad)))
    if area <= 0.0:
        return 0.0
    frame = np.array([[0, 0], [width, 0], [width, height], [0, height]],
                     np.float32).reshape(-1, 1, 2)
    try:
        common, _ = cv2.intersectConvexConvex(quad, frame)
    except cv2.error:  # not convex: no trustworthy corners either
        return 0.0
    return min(1.0, max(0.0, float(common)) / area)


#: A pixel with a channel at this level is saturated: the scene may be brighter.
SATURATED_LEVEL = 255


def saturated_share(image: np.ndarray, corners: FloatArray) -> float:
    """Share of the quadrilateral's pixels (those inside the image) with a saturated
    channel; 0 when none of it is in the image."""
    quad = np.asarray(corners, np.float64)
    height, width = image.shape[:2]
    x0, y0 = np.maximum(np.floor(quad.min(axis=0)).astype(int), 0)
    x1 = int(min(np.ceil(quad[:, 0].max()) + 1, width))
    y1 = int(min(np.ceil(quad[:, 1].max()) + 1, height))
    if x1 <= x0 or y1 <= y0:
        return 0.0
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    cv2.fillConvexPoly(mask, np.round(quad - (x0, y0)).astype(np.int32), 255)
    inside = cv2.countNonZero(mask)
    if inside == 0:
        return 0.0
    # pixels with every channel under the level, by OpenCV (no per-channel temporaries):
    # a frame's plates cost 0.3 ms a frame in numpy (issue 23)
    crop = image[y0:y1, x0:x1]
    channels = 1 if crop.ndim == 2 else crop.shape[2]
    below = cv2.inRange(crop, (0,) * channels, (SATURATED_LEVEL - 1,) * channels)
    cool = cv2.countNonZero(cv2.bitwise_and(below, mask))
    return float(inside - cool) / float(inside)
