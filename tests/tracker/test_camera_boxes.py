"""Frame rectification and the pixel-box helpers (tracker/camera.py, tracker/boxes.py)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracker.boxes import box_corners, box_iou, clip_box, in_view_share, saturated_share
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


def test_rectifier_scale_is_how_far_a_raw_pixel_step_moves_in_the_rectified_frame() -> None:
    """``scale_at``: 1 at the centre and everywhere without distortion; towards the edge of a
    barrel-distorted frame, the RMS over two perpendicular directions of how far a 1 px
    step of the raw (distorted) image moves a point once rectified."""
    cam = CameraModel(distortion=(-0.28, 0.09, 0.0005, -0.0005, 0.0))
    rect = Rectifier(cam)
    assert rect.scale_at((cam.cx, cam.cy)) == pytest.approx(1.0, abs=1e-3)
    assert Rectifier(CameraModel(distortion=(0.0,) * 5)).scale_at((600.0, 450.0)) == \
        pytest.approx(1.0, abs=1e-9)
    edge = (600.0, 450.0)  # a rectified point near the lower-right corner
    ray = np.array([[(edge[0] - cam.cx) / cam.fx, (edge[1] - cam.cy) / cam.fy, 1.0]])
    raw = cam.project_camera_points(ray)[0]
    steps = raw + np.array([[0.0, 0.0], [0.5, 0.0], [-0.5, 0.0], [0.0, 0.5], [0.0, -0.5]])
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    back = cv2.undistortPoints(steps.reshape(-1, 1, 2), cam.matrix, cam.dist_coeffs, None, None,
                               cam.matrix, criteria).reshape(-1, 2)
    assert np.linalg.norm(back[0] - edge) < 1e-3  # the round trip lands where it started
    # the raw -> rectified Jacobian from the two unit steps; its RMS gain over directions
    jac = np.column_stack([back[1] - back[2], back[3] - back[4]])
    expected = np.sqrt(np.sum(jac**2) / 2.0)
    assert expected > 1.2  # the lens squeezes the edge: rectifying stretches it
    assert rect.scale_at(edge) == pytest.approx(expected, rel=1e-3)


def test_saturated_share_counts_pixels_inside_the_quadrilateral() -> None:
    image = np.zeros((100, 100, 3), np.uint8)
    image[:, 50:, 2] = 255  # the right half has a saturated red channel
    quad = box_corners((30.0, 20.0, 40.0, 40.0))  # 30..70: half of it on each side
    assert saturated_share(image, quad) == pytest.approx(0.5, abs=0.03)
    assert saturated_share(image, box_corners((5.0, 5.0, 30.0, 30.0))) == 0.0
    assert saturated_share(image, box_corners((80.0, 10.0, 40.0, 20.0))) == 1.0  # in view: all hot
    assert saturated_share(image, box_corners((200.0, 10.0, 5.0, 5.0))) == 0.0  # out of view
    assert saturated_share(image[:, :, 2], quad) == pytest.approx(0.5, abs=0.03)  # grey


def test_saturated_share_is_any_channel_at_255_counted_exactly() -> None:
    """One channel at 255 makes a pixel saturated, 254 in every channel does not; the share
    is the exact count over the quadrilateral's pixels (issue 23 counts them in OpenCV)."""
    image = np.full((40, 40, 3), 254, np.uint8)
    image[10:20, 10:15, 1] = 255  # 50 pixels with only green saturated
    image[10:20, 15:20] = 255  # 50 pixels with every channel saturated
    quad = np.array([[10.0, 10.0], [29.0, 10.0], [29.0, 19.0], [10.0, 19.0]])  # 20 x 10 px
    assert saturated_share(image, quad) == 100 / 200
    assert saturated_share(image[:, :, 0], quad) == 50 / 200  # grey: only the 255s
    assert saturated_share(np.full((40, 40, 3), 254, np.uint8), quad) == 0.0


def test_box_helpers() -> None:
    assert box_iou((0, 0, 10, 10), (5, 0, 10, 10)) == pytest.approx(50 / 150)
    assert clip_box((-5, -5, 20, 20), 10, 10) == (0.0, 0.0, 10.0, 10.0)
    assert clip_box((8, 8, 10, 10), 10, 10) is None  # 2 x 2 px left: too little to track
    quad = box_corners((90.0, 40.0, 20.0, 10.0))
    assert quad.tolist() == [[90, 40], [110, 40], [110, 50], [90, 50]]
    assert in_view_share(quad, 100, 100) == pytest.approx(0.5)  # half of it past x = 100
    assert in_view_share(quad, 200, 100) == pytest.approx(1.0)
    assert in_view_share(np.zeros((4, 2)), 100, 100) == 0.0  # degenerate
