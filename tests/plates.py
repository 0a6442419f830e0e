"""A textured plate for the tests of corners and tracks (not a test module)."""

from __future__ import annotations

import cv2
import numpy as np

from tracker.acquire import Reference, ReferenceMatcher


def textured_plate(seed: int) -> tuple[np.ndarray, ReferenceMatcher, Reference]:
    """A 120x80 plate of blurred random grey blocks drawn by ``seed``: its grey levels, and
    its reference ("plate") in a matcher of its own."""
    rng = np.random.default_rng(seed)
    blocks = rng.integers(40, 220, (8, 12)).astype(np.uint8)
    grey = cv2.GaussianBlur(cv2.resize(blocks, (120, 80), interpolation=cv2.INTER_NEAREST),
                            (5, 5), 1.0)
    matcher = ReferenceMatcher()
    return grey, matcher, matcher.add("plate", cv2.merge([grey, grey, grey]))
