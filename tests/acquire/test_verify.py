"""tracker.verify: the warped appearance confirms a plate whatever the light and refuses
a wrong place; the alignment's fit gives the corners' sigma; outlines are compared."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracker.acquire import ReferenceMatcher, homography_to
from tracker.verify import (
    appearance_ncc,
    best_shift,
    check_appearance,
    check_appearance_near,
    detail_ncc,
    fit_corner_sigma,
    quad_iou,
)


def textured(rng: np.random.Generator, w: int, h: int, cell: int) -> np.ndarray:
    coarse = rng.integers(0, 256, (h // cell + 1, w // cell + 1, 3), dtype=np.uint8)
    big = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(big)


def scene(angle_deg: float = 30.0, gain: float = 1.0, offset: float = 0.0, noise: float = 0.0,
          seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 320x240 frame with a 120x80 plate drawn rotated at about (160, 120), 90 px wide;
    (frame, plate, its true corners)."""
    rng = np.random.default_rng(seed)
    plate = textured(rng, 120, 80, 6)
    frame = textured(np.random.default_rng(seed + 100), 320, 240, 9)
    a = np.deg2rad(angle_deg)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    local = np.array([[-45, -30], [45, -30], [45, 30], [-45, 30]], np.float64)
    corners = local @ rot.T + (160.0, 120.0)
    ref = ReferenceMatcher().add("p", plate)
    hom = homography_to(ref, corners)
    warped = cv2.warpPerspective(plate, hom, (320, 240))
    inside = cv2.warpPerspective(np.ones((80, 120), np.uint8), hom, (320, 240)).astype(bool)
    frame[inside] = warped[inside]
    out = frame.astype(np.float64) * gain + offset
    out += np.random.default_rng(seed + 7).normal(0.0, noise, out.shape)
    return np.clip(out, 0, 255).astype(np.uint8), plate, corners


def test_the_plate_correlates_in_any_light_and_a_wrong_place_does_not() -> None:
    for gain, offset in ((1.0, 0.0), (0.5, 10.0), (1.3, -20.0)):
        frame, plate, corners = scene(gain=gain, offset=offset, noise=3.0)
        ref = ReferenceMatcher().add("p", plate)
        assert appearance_ncc(ref, frame, homography_to(ref, corners)) > 0.8
    frame, plate, corners = scene()
    ref = ReferenceMatcher().add("p", plate)
    away = corners + np.array([-110.0, 60.0])  # the background beside it
    assert appearance_ncc(ref, frame, homography_to(ref, away)) < 0.3


def test_the_fit_sigma_grows_with_noise_and_with_a_misalignment() -> None:
    sig = []
    for noise in (1.0, 8.0):
        frame, plate, corners = scene(noise=noise)
        ref = ReferenceMatcher().add("p", plate)
        sig.append(fit_corner_sigma(ref, frame, homography_to(ref, corners)))
    assert sig[0] is not None and sig[1] is not None
    assert sig[1] > 2.0 * sig[0]
    frame, plate, corners = scene(noise=1.0)
    ref = ReferenceMatcher().add("p", plate)
    off = fit_corner_sigma(ref, frame, homography_to(ref, corners + np.array([1.5, -1.0])))
    assert off is not None and off > 2.0 * sig[0]


def test_outlines_are_compared_as_quadrilaterals() -> None:
    _, _, corners = scene(angle_deg=35.0)
    assert quad_iou(corners, corners) == pytest.approx(1.0)
    assert quad_iou(corners, corners + np.array([45.0, 0.0])) < 0.6
    assert quad_iou(corners, corners + np.array([400.0, 0.0])) == 0.0


def test_broad_shading_alone_is_not_the_plate() -> None:
    """Ground whose shading follows the plate's broad light and dark areas (what an
    alignment fitted to plain ground makes of it) correlates with the plate; its detail
    does not."""
    rng = np.random.default_rng(3)
    broad = np.tile(np.linspace(40.0, 210.0, 120), (80, 1))  # dark left, bright right
    plate = np.clip(broad + rng.normal(0, 25, (80, 120)), 0, 255).astype(np.uint8)
    ground = np.clip(broad + rng.normal(0, 25, (80, 120)), 0, 255).astype(np.uint8)
    frame = np.full((240, 320, 3), 120, np.uint8)
    frame[80:160, 100:220] = ground[..., None]
    ref = ReferenceMatcher().add("p", cv2.cvtColor(plate, cv2.COLOR_GRAY2BGR))
    hom = homography_to(ref, np.array([[99.5, 79.5], [219.5, 79.5], [219.5, 159.5],
                                       [99.5, 159.5]]))
    assert appearance_ncc(ref, frame, hom) > 0.6
    assert detail_ncc(ref, frame, hom) < 0.3
    frame[80:160, 100:220] = plate[..., None]
    assert detail_ncc(ref, frame, hom) > 0.9


def test_a_box_placed_outline_a_few_pixels_off_is_found_within_its_reach() -> None:
    """A track without corners is checked where its box puts the outline, a few pixels off
    the plate: the search finds the shift back (check_appearance_near), the check at the
    placed outline alone fails, and the background beside the plate still fails."""
    frame, plate, corners = scene(noise=3.0, seed=2)
    ref = ReferenceMatcher().add("p", plate)
    off = homography_to(ref, corners + np.array([5.0, -4.0]))
    assert best_shift(ref, frame, off, 8) == (-5, 4)
    assert check_appearance(ref, frame, off)[0] < 0.5
    assert check_appearance_near(ref, frame, off, 8)[0] > 0.8
    assert best_shift(ref, frame, off, 0) == (0, 0)
    away = homography_to(ref, corners + np.array([-110.0, 60.0]))
    assert check_appearance_near(ref, frame, away, 8)[0] < 0.3
