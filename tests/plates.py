"""A textured plate for the tests of corners and tracks (not a test module)."""

from __future__ import annotations

import cv2
import numpy as np

from companion.corners import Corners
from companion.perception_types import PerceptionConfig, Track
from tracker.acquire import Reference, ReferenceMatcher, project_corners
from tracker.adaptive import AdaptiveTracker
from tracker.camera import CameraModel


def textured_plate(seed: int) -> tuple[np.ndarray, ReferenceMatcher, Reference]:
    """A 120x80 plate of blurred random grey blocks drawn by ``seed``: its grey levels, and
    its reference ("plate") in a matcher of its own."""
    rng = np.random.default_rng(seed)
    blocks = rng.integers(40, 220, (8, 12)).astype(np.uint8)
    grey = cv2.GaussianBlur(cv2.resize(blocks, (120, 80), interpolation=cv2.INTER_NEAREST),
                            (5, 5), 1.0)
    matcher = ReferenceMatcher()
    return grey, matcher, matcher.add("plate", cv2.merge([grey, grey, grey]))


def plate_track(image: np.ndarray, matcher: ReferenceMatcher, ref: Reference,
                at: tuple[float, float, float, float], box: tuple[float, float, float, float]
                ) -> tuple[Corners, Track, np.ndarray]:
    """The plate drawn at ``at`` (x, y, width, height in px) in ``image``: a Corners on
    it and a track whose tracker box is ``box`` (the part that was in view when it was
    acquired, ``partial_box``), and the true homography."""
    x, y, w, h = at
    truth = np.array([[w / ref.size_px[0], 0.0, x], [0.0, h / ref.size_px[1], y],
                      [0.0, 0.0, 1.0]])
    tracker = AdaptiveTracker()
    tracker.init(image, box)
    track = Track("plate", tracker, box, truth, corners=project_corners(ref, truth),
                  partial_box=True)
    return Corners(CameraModel(), PerceptionConfig(), {"plate": ref}, matcher), track, truth
