"""Frames and rotations shared by the whole project (pure numpy).

Conventions (fixed; every part uses them):

* World: local NED (north, east, down) in metres about a configured WGS84 origin.
* Body: FRD (forward, right, down).  ``R_ned_body = Rz(yaw) @ Ry(pitch) @ Rx(roll)``
  (aerospace ZYX Euler angles, radians), so ``p_ned = R_ned_body @ p_body``.
* Camera: OpenCV optical frame (x right, y down, z forward along the optical axis).
* Camera mount: ``mount_rpy_deg`` are ZYX Euler angles of the camera in the body frame.
  At [0, 0, 0] the camera looks along body +x with image x to body +y and image y to
  body +z; pitch -90 looks straight down.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: Camera optical axes expressed in the body frame at a zero mount:
#: columns are camera x (body +y), camera y (body +z), camera z (body +x).
R_BODY_CAM_ZERO_MOUNT: FloatArray = np.array(
    [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=np.float64
)


def rot_x(a: float) -> FloatArray:
    """Rotation about x by ``a`` radians."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> FloatArray:
    """Rotation about y by ``a`` radians."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> FloatArray:
    """Rotation about z by ``a`` radians."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_from_rpy(roll_rad: float, pitch_rad: float, yaw_rad: float) -> FloatArray:
    """ZYX Euler angles -> rotation matrix ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    return rot_z(yaw_rad) @ rot_y(pitch_rad) @ rot_x(roll_rad)


def rpy_from_rotation(r: FloatArray) -> tuple[float, float, float]:
    """Inverse of :func:`rotation_from_rpy` (pitch in [-pi/2, pi/2])."""
    m = r.tolist()
    pitch = math.asin(min(1.0, max(-1.0, -m[2][0])))
    return math.atan2(m[2][1], m[2][2]), pitch, math.atan2(m[1][0], m[0][0])


def mount_rotation(mount_rpy_deg: tuple[float, float, float]) -> FloatArray:
    """``R_body_cam`` for a camera mount given as roll/pitch/yaw in degrees (body FRD)."""
    roll, pitch, yaw = np.deg2rad(np.asarray(mount_rpy_deg, dtype=np.float64))
    return rotation_from_rpy(float(roll), float(pitch), float(yaw)) @ R_BODY_CAM_ZERO_MOUNT
