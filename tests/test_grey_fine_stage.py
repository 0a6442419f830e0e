"""A plate with little colour aligns its fine stage on grey levels alone
(``perception.ecc_grey_from_ratio``) and, in the simulator's layer, states its corners by
their fit (``perception.grey_fit_sigma``): docs/decisions.md, "Grey levels alone on a plate
with little colour".  Under JPEG a photograph's mixed plane is mostly the frame's chroma
error, which the mix scales up to unit spread; a coloured sign keeps the mixed plane."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from companion.corner_noise import CornerNoise
from companion.corners import ecc, grey_aligned
from companion.perception_types import PerceptionConfig, Track
from companion.settings import SIM_LAYERS, load_settings
from tracker.acquire import (
    ReferenceMatcher,
    homography_to,
    luma_chroma_ratio,
    project_corners,
    reference_quad,
)
from tracker.adaptive import AdaptiveTracker
from tracker.camera import CameraModel
from tracker.pose.config import PoseConfig

#: a colour feature of the kind the tracker picks (R - B)
FEATURE = (-0.5, 0.0, 0.5)


def photo_plate(tint: float) -> np.ndarray:
    """A 120x80 grey-textured plate (a photograph of a wall) whose red and blue drift by
    ``tint`` grey levels (1-sigma) over broad patches."""
    rng = np.random.default_rng(3)
    blocks = rng.integers(40, 220, (8, 12)).astype(np.float32)
    grey = cv2.GaussianBlur(cv2.resize(blocks, (120, 80), interpolation=cv2.INTER_NEAREST),
                            (5, 5), 1.0)
    drift = cv2.GaussianBlur(cv2.resize(rng.normal(0, tint, (4, 6)).astype(np.float32),
                                        (120, 80), interpolation=cv2.INTER_NEAREST), (9, 9), 3.0)
    return np.clip(np.dstack([grey - drift, grey, grey + drift]), 0, 255).astype(np.uint8)


def sign_plate() -> np.ndarray:
    """A 120x80 sign of red, green and blue blocks."""
    rng = np.random.default_rng(5)
    colours = np.array([[40, 40, 200], [40, 150, 40], [200, 90, 40]], np.uint8)  # BGR
    blocks = colours[rng.integers(0, 3, (8, 12))]
    return cv2.GaussianBlur(cv2.resize(blocks, (120, 80), interpolation=cv2.INTER_NEAREST),
                            (5, 5), 1.0)


def corner_errors(bgr: np.ndarray, grey_from_ratio: float, quality: int = 90) -> np.ndarray:
    """Largest corner error (px) of a running track's alignment of ``bgr``, drawn 60 px wide
    at six sub-pixel places in a JPEG frame of ``quality``, started 1 % large and 0.3 px
    off, on :data:`FEATURE` with ``perception.ecc_grey_from_ratio`` at
    ``grey_from_ratio``."""
    ref = ReferenceMatcher().add("plate", bgr)
    w, h = ref.size_px
    config = dataclasses.replace(PerceptionConfig(), ecc_grey_from_ratio=grey_from_ratio)
    rng = np.random.default_rng(1)
    out = []
    for _ in range(6):
        centre = np.array([320.0, 240.0]) + rng.uniform(-0.5, 0.5, 2)
        quad = (reference_quad(ref) - np.array([w / 2 - 0.5, h / 2 - 0.5])) * (60 / w) + centre
        truth = homography_to(ref, quad)
        frame = cv2.warpPerspective(bgr, truth, (640, 480), flags=cv2.INTER_AREA,
                                    borderValue=(60, 90, 70))
        _, jpeg = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, quality])
        frame = cv2.imdecode(jpeg, cv2.IMREAD_COLOR)
        start = homography_to(ref, (quad - centre) * 1.01 + centre + 0.3)
        found = ecc(config, ref, frame, start, verify=False, weights=FEATURE)
        assert found is not None
        out.append(float(np.abs(project_corners(ref, found) - quad).max()))
    return np.asarray(out)


def test_the_ratio_tells_a_photograph_from_a_coloured_sign() -> None:
    grey = photo_plate(0.0)
    assert luma_chroma_ratio(grey) >= 1e5  # no chroma at all: a crop of grey video
    assert 50 < luma_chroma_ratio(photo_plate(8.0)) < 1000  # 129 seen
    assert luma_chroma_ratio(sign_plate()) < 2.0
    config = dataclasses.replace(PerceptionConfig(), ecc_grey_from_ratio=4.0)
    matcher = ReferenceMatcher()
    assert grey_aligned(config, matcher.add("photo", photo_plate(8.0)))
    assert not grey_aligned(config, matcher.add("sign", sign_plate()))
    assert not grey_aligned(PerceptionConfig(), matcher.references["photo"])  # off: 0


def test_the_deployment_keeps_the_mixed_plane_and_the_simulator_aligns_grey() -> None:
    """Measured on simulated JPEG frames only: off until a real camera's are measured."""
    assert load_settings().perception.ecc_grey_from_ratio == 0.0
    assert not load_settings().perception.grey_fit_sigma
    sim = load_settings(shipped=SIM_LAYERS).perception
    assert sim.ecc_grey_from_ratio == 4.0 and sim.grey_fit_sigma


@pytest.mark.parametrize("tint", [3.0, 8.0])
def test_a_photographs_corners_hold_on_grey_levels_in_a_jpeg_frame(tint: float) -> None:
    """On the mixed plane the frame's chroma error holds the corners 0.1-0.6 px off; on grey
    levels alone they are a few hundredths off (0.02-0.05 px seen)."""
    mixed, grey = corner_errors(photo_plate(tint), 0.0), corner_errors(photo_plate(tint), 4.0)
    assert np.median(mixed) > 0.12
    assert grey.max() < 0.07
    assert np.median(grey) < 0.3 * np.median(mixed)


def test_a_coloured_sign_keeps_the_mixed_plane() -> None:
    on, off = corner_errors(sign_plate(), 4.0), corner_errors(sign_plate(), 0.0)
    assert np.array_equal(on, off)  # the same alignment, to the bit


def _noise(config: PerceptionConfig) -> CornerNoise:
    return CornerNoise(CameraModel(), config, PoseConfig(), None, [], frozenset({"photo"}))


def test_a_grey_plate_is_stated_by_its_fit_only_when_on() -> None:
    corners = ((300.0, 200.0), (340.0, 200.0), (340.0, 227.0), (300.0, 227.0))
    on = dataclasses.replace(PerceptionConfig(), grey_fit_sigma=True, fit_sigma_scale=1.0)
    off = dataclasses.replace(on, grey_fit_sigma=False)
    model = _noise(on).sigma(corners, 1.0)
    assert model is not None
    fit = 0.25 * model  # an alignment fitting far better than the size model says

    def track(lid: str) -> Track:
        return Track(lid, AdaptiveTracker(), (300.0, 200.0, 40.0, 27.0), None,
                     fit_sigma=fit)

    assert _noise(on).stated(track("photo"), corners, 1.0) == pytest.approx(fit)
    assert _noise(off).stated(track("photo"), corners, 1.0) == pytest.approx(model)
    assert _noise(on).stated(track("sign"), corners, 1.0) == pytest.approx(model)
    assert _noise(on).stated(track("photo"), None, 1.0) is None


def test_a_mixed_plane_plate_states_its_own_modes() -> None:
    """``lossy_mixed_corner_mode_sigma_rel`` reaches a plate aligned on the mixed plane
    on a lossy frame (a mode at 0 takes the pose's), not a grey-aligned one nor any plate
    on a lossless frame; unset, no plate states its own."""
    rel = (1.0, 0.0, 0.8, 1.2, 0.0, 0.7, 0.9, 1.1)
    config = dataclasses.replace(PerceptionConfig(), lossy_mixed_corner_mode_sigma_rel=rel)
    pose = PoseConfig(corner_mode_sigma_rel=(0.5,) * 8)
    noise = CornerNoise(CameraModel(), config, pose, None, [], frozenset({"photo"}))

    def track(lid: str) -> Track:
        return Track(lid, AdaptiveTracker(), (300.0, 200.0, 40.0, 27.0), None)

    assert noise.modes(track("sign")) is None
    noise.lossy = True
    assert noise.modes(track("sign")) == (1.0, 0.5, 0.8, 1.2, 0.5, 0.7, 0.9, 1.1)
    assert noise.modes(track("photo")) is None
    unset = _noise(PerceptionConfig())
    unset.lossy = True
    assert unset.modes(track("sign")) is None
