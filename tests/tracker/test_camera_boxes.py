"""Frame rectification and the pixel-box helpers (tracker/camera.py, tracker/boxes.py)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracker.boxes import box_corners, box_iou, clip_box, in_view_share
from tracker.camera import CameraModel, Rectifier


def test_rectified_frame_puts_a_point_where_the_pinhole_camera_would() -> None:
    """A dot drawn where the distorted lens images a point lands, after rectification,
    where the same camera without distortion images it (and the rectifier's camera is that
    camera)."""
    cam = CameraModel(distortion=(-0.28, 0.09, 0.0005, -0.0005, 0.0))
    rect = Rectifier(cam)
    assert rect.camera.distortion == (0.0,) * 5 and rect.camera.fx == cam.fx
    point = np.array([[1.4, -0.9, 4.0]])  # camera frame, off-centre where distortion is strong
    distorted = cam.project_camera_points(point)[0]
    pinhole = rect.camera.project_camera_points(point)[0]
    assert np.linalg.norm(distorted - pinhole) > 10.0  # the lens really moves it
    image = np.zeros((cam.height, cam.width, 3), np.uint8)
    cv2.circle(image, (round(distorted[0] * 16), round(distorted[1] * 16)), 5 * 16,
               (255, 255, 255), -1, cv2.LINE_AA, 4)
    grey = rect(image)[:, :, 0].astype(np.float64)
    ys, xs = np.mgrid[: grey.shape[0], : grey.shape[1]]
    centre = np.array([(xs * grey).sum(), (ys * grey).sum()]) / grey.sum()
    assert np.linalg.norm(centre - pinhole) < 0.5


def test_box_helpers() -> None:
    assert box_iou((0, 0, 10, 10), (5, 0, 10, 10)) == pytest.approx(50 / 150)
    assert clip_box((-5, -5, 20, 20), 10, 10) == (0.0, 0.0, 10.0, 10.0)
    assert clip_box((8, 8, 10, 10), 10, 10) is None  # 2 x 2 px left: too little to track
    quad = box_corners((90.0, 40.0, 20.0, 10.0))
    assert quad.tolist() == [[90, 40], [110, 40], [110, 50], [90, 50]]
    assert in_view_share(quad, 100, 100) == pytest.approx(0.5)  # half of it past x = 100
    assert in_view_share(quad, 200, 100) == pytest.approx(1.0)
    assert in_view_share(np.zeros((4, 2)), 100, 100) == 0.0  # degenerate
