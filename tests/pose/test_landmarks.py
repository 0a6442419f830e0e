"""Corner geometry: the documented order matches what a camera in front sees."""

from __future__ import annotations

import numpy as np

from tracker.camera import CameraModel
from tracker.pose import MapLandmark, face_rotation, landmark_corners_ned
from tracker.pose.landmarks import face_corners


def test_face_rotation_is_a_proper_rotation_for_upright_and_flat() -> None:
    for facing in (None, 0.0, 90.0, 180.0, 271.5):
        r = face_rotation(facing)
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) > 0.999


def test_upright_sign_facing_south_has_top_left_at_west_top() -> None:
    lm = MapLandmark("S", (10.0, 0.0, -3.0), 2.0, 1.0, 180.0)
    c = landmark_corners_ned(lm)
    # viewer stands south looking north: left = west (east < 0), top = up (down smaller)
    np.testing.assert_allclose(c[0], [10.0, -1.0, -3.5])
    np.testing.assert_allclose(c[1], [10.0, 1.0, -3.5])
    np.testing.assert_allclose(c[2], [10.0, 1.0, -2.5])
    np.testing.assert_allclose(c[3], [10.0, -1.0, -2.5])


def test_flat_landmark_top_edge_points_north() -> None:
    lm = MapLandmark("F", (0.0, 0.0, 0.0), 2.0, 4.0, None)
    c = landmark_corners_ned(lm)
    np.testing.assert_allclose(c[0], [2.0, -1.0, 0.0])  # top-left = north-west
    np.testing.assert_allclose(c[2], [-2.0, 1.0, 0.0])  # bottom-right = south-east


def test_corner_order_is_opencv_ippe_square_order_in_the_image() -> None:
    """A camera in front sees corner 0 top-left, 1 top-right, 2 bottom-right, 3 bottom-left."""
    cam = CameraModel()
    for facing, pos, yaw in ((180.0, (-10.0, 0.0, 0.0), 0.0), (90.0, (0.0, 10.0, 0.0), -np.pi / 2)):
        lm = MapLandmark("S", (0.0, 0.0, 0.0), 1.0, 1.0, facing)
        uv = cam.project_camera_points(
            cam.world_to_camera(landmark_corners_ned(lm), np.array(pos), (0.0, 0.0, yaw))
        )
        assert uv[0, 0] < uv[1, 0] and uv[0, 1] < uv[3, 1]
        assert uv[2, 0] > uv[3, 0] and uv[2, 1] > uv[1, 1]
    half = face_corners(2.0, 2.0)[:, :2]
    np.testing.assert_allclose(half, [[-1, 1], [1, 1], [1, -1], [-1, -1]])
