"""A small plate's outer ring (``perception.ecc_band_from_px``): where the frame's pixels
mix the plate with the ground behind it, a template of the plate alone pulls the aligned
outline towards the plate's inside when the ring is kept (48, the setting until
2026-12-05); left out (the default), the outline stays where it is (docs/decisions.md,
"A small plate's ring is left out too")."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from companion.corners import ecc
from companion.perception_types import PerceptionConfig
from tests.plates import textured_plate
from tracker.acquire import homography_to, project_corners, reference_quad
from tracker.pose.inputs import outline_basis

SCALE_MODE = 3  # outline_basis: shift x, shift y, rotation, scale, ...


def scale_errors(band_from_px: int) -> np.ndarray:
    """The aligned outline's error along its scale mode (px) for a 56 px wide textured
    plate (``tests.plates.textured_plate``) on a dark ground (its template's short side
    37 px), started 1 % large and 0.3 px off, six sub-pixel placements."""
    rng = np.random.default_rng(3)
    grey, _, ref = textured_plate(3)
    w, h = ref.size_px
    config = dataclasses.replace(PerceptionConfig(), ecc_band_from_px=band_from_px)
    out = []
    for _ in range(6):
        centre = np.array([320.0, 240.0]) + rng.uniform(-0.5, 0.5, 2)
        quad = (reference_quad(ref) - np.array([w / 2 - 0.5, h / 2 - 0.5])) * (56 / w) + centre
        truth = homography_to(ref, quad)
        plate = cv2.warpPerspective(grey, truth, (640, 480), flags=cv2.INTER_LINEAR)
        on = cv2.warpPerspective(np.ones((h, w), np.uint8), truth, (640, 480),
                                 flags=cv2.INTER_NEAREST)
        frame = np.repeat(np.where(on > 0, plate, 20).astype(np.uint8)[:, :, None], 3, axis=2)
        start = homography_to(ref, (quad - centre) * 1.01 + centre + 0.3)
        found = ecc(config, ref, frame, start, verify=False)
        assert found is not None
        err = project_corners(ref, found) - quad
        out.append(float((outline_basis(quad).T @ err.ravel())[SCALE_MODE]))
    return np.asarray(out)


def test_a_small_plates_kept_ring_pulls_its_outline_in() -> None:
    kept = scale_errors(48)  # the template's short side is 37 px: its ring kept
    assert kept.mean() < -0.2  # the ground's dark pixels in the ring's samples


def test_by_default_a_small_plates_ring_is_left_out_and_its_outline_stays() -> None:
    left_out = scale_errors(PerceptionConfig().ecc_band_from_px)
    assert abs(left_out.mean()) < 0.1 and left_out.std() < 0.1
