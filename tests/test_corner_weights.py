"""Corners of a grey reference photo's plate seen under coloured light (issue 25): the
tracker picks its colour feature on the frame, where the plate carries the light's cast;
the reference has none of it, so its plane in that feature is flat, and the alignment
falls back to grey levels instead of failing on every frame."""

from __future__ import annotations

import cv2
import numpy as np

from companion.corners import Corners
from companion.perception_types import PerceptionConfig, Track
from tracker.acquire import ReferenceMatcher, project_corners
from tracker.camera import CameraModel

WARM = (-1.0, 0.0, 1.0)  # (b, g, r) weights: red minus blue, the warm cast's feature


def scene(grey_reference: bool) -> tuple[Corners, Track, np.ndarray, np.ndarray]:
    """A textured 120x80 reference, pasted at (260, 200) into a frame under warm light;
    the track starts 2 px off with the warm feature as its alignment weights."""
    rng = np.random.default_rng(3)
    blocks = rng.integers(40, 220, (8, 12)).astype(np.uint8)
    grey = cv2.resize(blocks, (120, 80), interpolation=cv2.INTER_NEAREST)
    grey = cv2.GaussianBlur(grey, (5, 5), 1.0)
    ref_bgr = cv2.merge([grey, grey, grey])
    if not grey_reference:  # a colour photo: red and blue vary apart
        ref_bgr[:, :, 0] = 255 - grey
    matcher = ReferenceMatcher()
    ref = matcher.add("plate", ref_bgr)
    frame = np.full((480, 640, 3), 90, np.uint8)
    frame[200:280, 260:380] = ref_bgr
    warm = frame.astype(np.float32) * np.array([0.7, 1.0, 1.3])  # BGR gains
    image = np.clip(warm, 0, 255).astype(np.uint8)
    sx, sy = 120 / ref.size_px[0], 80 / ref.size_px[1]
    truth = np.array([[sx, 0.0, 260.0], [0.0, sy, 200.0], [0.0, 0.0, 1.0]])
    start = np.array([[1.0, 0.0, 2.0], [0.0, 1.0, -1.5], [0.0, 0.0, 1.0]]) @ truth
    track = Track("plate", None, (260.0, 200.0, 120.0, 80.0), start,  # type: ignore[arg-type]
                  align_weights=WARM)
    corners = Corners(CameraModel(), PerceptionConfig(), {"plate": ref}, matcher)
    return corners, track, image, project_corners(ref, truth)


def test_a_grey_reference_is_aligned_on_grey_levels_under_a_colour_cast() -> None:
    corners, track, image, truth = scene(grey_reference=True)
    assert corners.weights(track) is None  # the reference is flat in the warm feature
    aligned = corners.align(track, image, track.homography)  # type: ignore[arg-type]
    assert aligned is not None
    found = project_corners(corners.references["plate"], aligned)
    assert np.abs(found - truth).max() < 0.5


def test_a_colour_reference_keeps_the_trackers_feature() -> None:
    corners, track, image, truth = scene(grey_reference=False)
    assert corners.weights(track) == WARM
    aligned = corners.align(track, image, track.homography)  # type: ignore[arg-type]
    assert aligned is not None
    found = project_corners(corners.references["plate"], aligned)
    assert np.abs(found - truth).max() < 0.5
