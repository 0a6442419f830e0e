"""A colour plane that follows the light's cast (``tracker.acquire.cast_gains``): issue 25's
warm cast scales R and B apart, so the frame's R - B plane is no longer the reference's up
to a gain and offset, and ECC on it shifted real seed 10's real-05 by 0.15-0.33 px.  The
frame's plane is projected with the feature's weights divided by each channel's gain on the
plate, which gives back the plane of the same frame without the cast (docs/decisions.md,
"A colour plane that follows the cast")."""

from __future__ import annotations

import numpy as np

from tests.acquire.test_acquire import place, textured_poster
from tracker.acquire import ReferenceMatcher, cast_gains, ecc_start, homography_to

QUAD = np.array([[250, 150], [370, 156], [368, 236], [252, 232]], np.float64)
CHROMA = (1.0, 0.0, -1.0)  # B - R


def cast(frame: np.ndarray, gains_bgr: tuple[float, float, float]) -> np.ndarray:
    return np.clip(frame.astype(np.float64) * np.asarray(gains_bgr), 0, 255).astype(np.uint8)


def test_white_light_of_any_level_has_no_cast() -> None:
    poster = textured_poster(5, 256, 170)
    ref = ReferenceMatcher().add("poster", poster)
    frame = place(poster, QUAD, seed=3)
    for level in (1.0, 0.6):
        gains = cast_gains(ref, cast(frame, (level,) * 3), QUAD)
        np.testing.assert_allclose(gains, 1.0, atol=0.02)


def test_a_warm_cast_is_measured_on_the_plate() -> None:
    poster = textured_poster(5, 256, 170)
    ref = ReferenceMatcher().add("poster", poster)
    gains = cast_gains(ref, cast(place(poster, QUAD, seed=3), (0.7, 1.0, 1.2)), QUAD)
    assert gains[0] / gains[2] < 0.65  # blue against red: 0.58 put on, clipping aside
    assert gains[0] < gains[1] < gains[2]


def test_the_frames_plane_under_a_cast_is_the_plane_without_it() -> None:
    poster = (textured_poster(5, 256, 170) * 0.7).astype(np.uint8)  # no channel clips
    ref = ReferenceMatcher().add("poster", poster)
    frame = place(poster, QUAD, seed=3)
    hom = homography_to(ref, QUAD + 1.0)
    plain = ecc_start(ref, frame, hom, CHROMA)
    warm = ecc_start(ref, cast(frame, (0.75, 1.0, 1.3)), hom, CHROMA)
    assert plain is not None and warm is not None
    # the same plane up to one gain (rounding to 8 bits aside); uncorrected, B - R under
    # the cast is not
    assert misfit(warm.roi, plain.roi) < 0.03
    raw = cast(frame, (0.75, 1.0, 1.3)).astype(np.float64) @ np.array(CHROMA)
    x0, y0 = int(plain.from_roi[0, 2]), int(plain.from_roi[1, 2])
    h, w = plain.roi.shape
    assert misfit(raw[y0:y0 + h, x0:x0 + w], plain.roi) > 0.2


def misfit(plane: np.ndarray, reference: np.ndarray) -> float:
    """RMS of ``plane`` less its best multiple of ``reference``, over ``reference``'s RMS."""
    p, r = plane.astype(np.float64).ravel(), reference.astype(np.float64).ravel()
    k = float(p @ r / (r @ r))
    return float(np.sqrt(np.mean((p - k * r) ** 2)) / np.sqrt(np.mean((k * r) ** 2)))
