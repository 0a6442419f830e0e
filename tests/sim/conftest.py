"""Small hand-made worlds for the simulator tests."""

from __future__ import annotations

import numpy as np
import pytest

from companion.sim.trajectory import KinematicState
from companion.sim.world import Quad, SimLandmark, World, WorldConfig, face_corners
from tracker.camera import CameraModel


def flat_landmark(
    lid: str, centre: tuple[float, float, float], size_m: tuple[float, float],
    facing_deg: float | None, colour: tuple[int, int, int] = (20, 40, 230),
) -> SimLandmark:
    """A bare plate (category "other": no pole, no facade) with a uniform texture."""
    c = np.asarray(centre, dtype=np.float64)
    tex = np.empty((40, 60, 3), np.uint8)
    tex[:] = colour
    quad = Quad(face_corners(c, size_m[0], size_m[1], facing_deg), tex, landmark_id=lid)
    return SimLandmark(lid, lid, "other", c, size_m[0], size_m[1], facing_deg, quad)


@pytest.fixture
def one_landmark_world() -> World:
    """One 3 x 2 m plate 10 m east of the origin, facing west, centre 4 m up."""
    return World([flat_landmark("L1", (0.0, 10.0, -4.0), (3.0, 2.0), 270.0)], WorldConfig(), 3)


@pytest.fixture
def east_state() -> KinematicState:
    """Hovering at the origin 4 m up, facing east, slightly rolled."""
    return KinematicState(0.0, (0.3, 0.0, -4.2), (0.0, 0.0, 0.0), (0.05, 0.02, np.deg2rad(88.0)))


@pytest.fixture
def camera() -> CameraModel:
    return CameraModel(mount_rpy_deg=(0.0, -5.0, 0.0))


@pytest.fixture
def make_landmark():  # type: ignore[no-untyped-def]
    """The :func:`flat_landmark` factory, for tests that build their own worlds."""
    return flat_landmark
