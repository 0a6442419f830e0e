"""Shared fixtures: a wall of signs in NED, cameras and noise-free observations."""

from __future__ import annotations

import numpy as np
import pytest

from tracker.camera import CameraModel
from tracker.geometry import FloatArray
from tracker.pose import MapLandmark, Observation, PoseFix
from tracker.pose.simulate import SensorNoise, observe_landmark

NO_NOISE = SensorNoise(pixel_sigma_px=0.0, centre_sigma_px=0.0)
TRUE_P = np.array([1.0, -0.5, -5.0])
TRUE_RPY = (0.02, -0.03, 0.05)


def wall() -> tuple[MapLandmark, ...]:
    """Four signs on different walls and depths, facing roughly south."""
    return (
        MapLandmark("A", (20.0, -6.0, -4.0), 1.2, 1.2, 180.0, "sign"),
        MapLandmark("B", (24.0, -1.0, -7.0), 1.0, 0.7, 185.0, "sign"),
        MapLandmark("C", (18.0, 3.0, -3.0), 1.2, 1.2, 170.0, "sign"),
        MapLandmark("D", (22.0, 7.0, -6.0), 1.5, 1.0, 200.0, "sign"),
    )


def see(
    landmarks: tuple[MapLandmark, ...],
    camera: CameraModel,
    p: FloatArray = TRUE_P,
    rpy: tuple[float, float, float] = TRUE_RPY,
    noise: SensorNoise = NO_NOISE,
    seed: int = 0,
) -> list[Observation]:
    """Observations of every landmark in view (noise-free unless ``noise`` says)."""
    rng = np.random.default_rng(seed)
    out = [observe_landmark(lm, camera, p, rpy, rng, noise) for lm in landmarks]
    return [o for o in out if o is not None]


def assert_exact(
    fix: PoseFix, p: np.ndarray, rpy: tuple[float, float, float] | None = None
) -> None:
    """Noise-free input: the error is negligible (< 1 %) against the fix's own 1-sigma."""
    sigma = np.sqrt(np.diag(fix.covariance))
    assert np.all(np.abs(np.asarray(fix.position_ned_m) - p) < 0.01 * sigma[:3])
    if rpy is not None:
        assert np.all(np.abs(np.asarray(fix.attitude_rpy_rad) - rpy) < 0.01 * sigma[3:])


@pytest.fixture
def camera() -> CameraModel:
    return CameraModel()
