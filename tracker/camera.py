"""Pinhole camera model with OpenCV distortion and a mount rotation (pure)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np
import numpy.typing as npt

from tracker.geometry import FloatArray, mount_rotation, rotation_from_rpy


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics (pixels), distortion (OpenCV order k1, k2, p1, p2[, k3...]) and mount.

    ``mount_rpy_deg``: the camera's roll/pitch/yaw in the body frame FRD (see
    :mod:`tracker.geometry`); pitch -90 looks straight down.
    """

    width: int = field(default=640, metadata={"ge": 1})
    height: int = field(default=480, metadata={"ge": 1})
    fx: float = field(default=525.0, metadata={"gt": 0})
    fy: float = field(default=525.0, metadata={"gt": 0})
    cx: float = 319.5
    cy: float = 239.5
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    mount_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def matrix(self) -> FloatArray:
        """The 3x3 intrinsic matrix K."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )

    @property
    def dist_coeffs(self) -> FloatArray:
        """Distortion coefficients as a float64 array (OpenCV order)."""
        return np.asarray(self.distortion, dtype=np.float64)

    @property
    def r_body_cam(self) -> FloatArray:
        """Rotation taking camera-frame vectors to the body frame."""
        return mount_rotation(self.mount_rpy_deg)

    def project_camera_points(self, points_cam: FloatArray) -> FloatArray:
        """Project Nx3 points in the camera frame to Nx2 distorted pixel coordinates.

        Points must be in front of the camera (z > 0); callers check visibility.
        """
        pts = np.asarray(points_cam, dtype=np.float64).reshape(-1, 1, 3)
        zero = np.zeros(3, dtype=np.float64)
        uv, _ = cv2.projectPoints(pts, zero, zero, self.matrix, self.dist_coeffs)
        return np.asarray(uv.reshape(-1, 2), dtype=np.float64)

    def world_to_camera(
        self,
        points_ned: FloatArray,
        vehicle_ned: FloatArray,
        vehicle_rpy_rad: tuple[float, float, float],
    ) -> FloatArray:
        """Nx3 NED world points -> Nx3 camera-frame points for a vehicle pose."""
        r_ned_body = rotation_from_rpy(*vehicle_rpy_rad)
        r_ned_cam = r_ned_body @ self.r_body_cam
        rel = np.asarray(points_ned, dtype=np.float64) - np.asarray(vehicle_ned, dtype=np.float64)
        return np.asarray(rel @ r_ned_cam, dtype=np.float64)  # = (R_ned_cam^T @ rel^T)^T


class Rectifier:
    """Removes a camera's lens distortion from whole frames (maps computed once).

    Alignment fits a homography, which a distorted plate does not follow: with barrel
    distortion (k1 = -0.28) its corners came out biased by pixels.  Rectified frames are
    pinhole images of :attr:`camera` (the same intrinsics, no distortion).
    """

    def __init__(self, camera: CameraModel) -> None:
        self.source = camera
        self.camera = replace(camera, distortion=(0.0,) * len(camera.distortion))
        self._maps = cv2.initUndistortRectifyMap(
            camera.matrix, camera.dist_coeffs, None, camera.matrix,
            (camera.width, camera.height), cv2.CV_16SC2)

    def __call__(self, image: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
        """``image`` (the camera's size) as the undistorted camera would have seen it."""
        return np.asarray(cv2.remap(image, self._maps[0], self._maps[1], cv2.INTER_LINEAR),
                          np.uint8)

    def scale_at(self, point_px: tuple[float, float]) -> float:
        """Rectified pixels per raw (distorted) pixel at a rectified point: the RMS over
        directions, ``sqrt((1/s1^2 + 1/s2^2) / 2)`` for the singular values ``s`` of the
        raw-from-rectified Jacobian.  Above 1 where rectification stretches the image (the
        edges of a barrel-distorted frame): there a rectified pixel holds less of the scene,
        and isotropic noise of one raw pixel becomes this many rectified pixels (RMS)."""
        u, v = point_px
        h = 0.5
        rect = np.array([[u - h, v], [u + h, v], [u, v - h], [u, v + h]], np.float64)
        k = self.camera.matrix
        rays = np.column_stack([(rect[:, 0] - k[0, 2]) / k[0, 0], (rect[:, 1] - k[1, 2]) / k[1, 1],
                                np.ones(4)])
        raw = self.source.project_camera_points(rays)
        jac = np.column_stack([raw[1] - raw[0], raw[3] - raw[2]]) / (2 * h)  # d raw / d rect
        sv = np.linalg.svd(jac, compute_uv=False)
        if sv[-1] <= 0.0:
            return 1.0
        return float(np.sqrt(np.mean(1.0 / sv**2)))
