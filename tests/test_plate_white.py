"""A plate's own white is not over-exposure (``Reference.white_share``): a white sign seen
with its white at 255 keeps its corners and their sigma; only the pixels saturated beyond
the plate's own white count (``Track.saturated``, which grows the corner sigma by
``saturated_sigma_gain`` and drops the corners over ``max_corner_saturated``).  The
survey's signs are 9 % and 15 % white and had their sigma grown 1.5-1.8 times for it
(docs/decisions.md, "A plate's own white is not over-exposure")."""

from __future__ import annotations

import cv2
import numpy as np

from companion.perception_types import PerceptionConfig
from tests.plates import plate_track
from tracker.acquire import ReferenceMatcher

AT = (200.0, 150.0, 240.0, 160.0)  # the plate in the frame: x, y, width, height (px)


def white_plate() -> np.ndarray:
    """A 120x80 plate of blurred grey blocks (40-220) whose right third is white (255)."""
    rng = np.random.default_rng(7)
    blocks = rng.integers(40, 220, (8, 12)).astype(np.uint8)
    grey = cv2.GaussianBlur(cv2.resize(blocks, (120, 80), interpolation=cv2.INTER_NEAREST),
                            (5, 5), 1.0)
    grey[:, 80:] = 255
    return grey


def followed(gain: float) -> float:
    """``Track.saturated`` after following the plate in a frame whose plate pixels are
    ``gain`` times the plate's levels (clipped at 255)."""
    grey = white_plate()
    matcher = ReferenceMatcher()
    ref = matcher.add("plate", cv2.merge([grey, grey, grey]))
    image = np.full((480, 640, 3), 90, np.uint8)
    x, y, w, h = (int(v) for v in AT)
    seen = np.clip(cv2.resize(grey, (w, h)).astype(np.float64) * gain, 0, 255).astype(np.uint8)
    image[y:y + h, x:x + w] = cv2.merge([seen, seen, seen])
    corners, track, _ = plate_track(image, matcher, ref, AT, AT)
    corners.follow(track, image, track.box)
    assert track.corners is not None
    return track.saturated


def test_the_reference_counts_its_own_white() -> None:
    grey = white_plate()
    ref = ReferenceMatcher().add("plate", cv2.merge([grey, grey, grey]))
    assert abs(ref.white_share - 1 / 3) < 0.01
    grey[:, 80:] = 200
    assert ReferenceMatcher().add("grey", cv2.merge([grey, grey, grey])).white_share == 0.0


def test_a_white_plate_seen_at_255_is_not_over_exposed() -> None:
    # a third of its pixels at 255 in the frame: under max_corner_saturated's 0.25 before
    # this rule, the corners would have been dropped
    assert PerceptionConfig().max_corner_saturated < 1 / 3
    assert followed(1.0) < 0.02


def test_pixels_saturated_beyond_its_white_still_count() -> None:
    # 1.6 x light: the blocks over 160 clip too, about a quarter of the plate more
    assert followed(1.6) > 0.15
