"""An over-exposed plate's clipped part is left out of its alignment
(``tracker.plate_light.unclipped``): a frame's pixel at 255 holds none of the detail the
template has there, and ECC's linear model of the levels pulls the outline towards the
clipped side (real seed 0's real-03 after the light step: 0.4-0.5 px; docs/decisions.md,
"An over-exposed plate's clipped part is left out of its alignment")."""

from __future__ import annotations

import cv2
import numpy as np

from tests.acquire.test_acquire import place
from tracker.acquire import (
    ReferenceMatcher,
    homography_to,
    project_corners,
    refine_ecc,
    resize_map,
)
from tracker.plate_light import MAX_LOST_SHARE, clipped, unclipped

QUAD = np.array([[250, 150], [370, 156], [368, 236], [252, 232]], np.float64)


def smooth_poster(seed: int, w: int = 256, h: int = 170) -> np.ndarray:
    """A photograph-like plate: smooth detail, darker on the left, brightest on the right
    (where a brighter light clips it first)."""
    rng = np.random.default_rng(seed)
    detail = cv2.GaussianBlur(rng.normal(0.0, 1.0, (h, w, 3)), (0, 0), 5)
    detail = (detail - detail.mean()) / detail.std()
    ramp = np.linspace(0.4, 1.0, w)[None, :, None]
    return np.asarray(np.clip((110 + 45 * detail) * ramp * 1.4, 0, 255), np.uint8)


def lit(frame: np.ndarray, gain: float) -> np.ndarray:
    return np.asarray(np.clip(frame.astype(np.float64) * gain, 0, 255), np.uint8)


def corner_error(poster: np.ndarray, frame: np.ndarray, clipped_out: bool) -> float:
    ref = ReferenceMatcher().add("plate", poster)
    hom = refine_ecc(ref, frame, homography_to(ref, QUAD + np.array([1.0, -0.7])),
                     clipped_out=clipped_out)
    assert hom is not None
    return float(np.sqrt(((project_corners(ref, hom) - QUAD) ** 2).mean()))


def test_a_plate_lit_past_what_the_frame_holds_is_aligned_on_its_unclipped_part() -> None:
    """Lit 1.5 times, a fifth of the plate clips: with that part in, its corners are
    0.24-0.38 px off; left out, 0.10-0.16 px."""
    for seed in range(5):
        poster = smooth_poster(seed)
        frame = lit(place(poster, QUAD, seed=3), 1.5)
        kept, left_out = corner_error(poster, frame, False), corner_error(poster, frame, True)
        assert left_out < 0.2, (seed, left_out)
        assert left_out < 0.75 * kept, (seed, left_out, kept)


def test_nothing_is_left_out_in_its_own_light_or_past_a_quarter() -> None:
    """In the light of its appearance image nothing is clipped; lit twice, over 40 % of it
    would be left out, and the alignment keeps all of it (``MAX_LOST_SHARE``)."""
    poster = smooth_poster(0)
    size = (poster.shape[1], poster.shape[0])
    own = np.asarray(cv2.mean(poster)[:3], np.float64)
    channels = [poster[:, :, c].astype(np.float32) for c in range(3)]
    frame = place(poster, QUAD, seed=3)
    crop, quad = frame[140:245, 240:380], QUAD - (240, 140)
    ref = ReferenceMatcher().add("plate", poster)
    warp = homography_to(ref, quad) @ np.linalg.inv(resize_map(ref.size_px, size))

    def keep_of(window: np.ndarray) -> np.ndarray | None:
        flat = clipped(window)
        return None if flat is None else unclipped(window, flat, quad, warp, channels, own)

    assert keep_of(crop) is None
    assert keep_of(lit(crop, 2.0)) is None
    assert corner_error(poster, frame, True) == corner_error(poster, frame, False)
    keep = keep_of(lit(crop, 1.5))
    assert keep is not None and 0.0 < 1.0 - keep.mean() <= 2 * MAX_LOST_SHARE
    # what is left out is mostly the plate's bright side, where its light takes it past
    # what the frame holds
    left, right = (1.0 - keep[:, : size[0] // 3].mean(), 1.0 - keep[:, -size[0] // 3:].mean())
    assert right > 5 * left, (left, right)
