"""How the image moved between two frames because the camera turned (issue 19).

A multirotor tilts to accelerate: the strict fake autopilot's vehicle (and a real copter
leaving a hover) rolls 11.5 deg within a frame or two, and every landmark in the image
jumps by tens of pixels (a plate at the image's edge by 60-80 px), far beyond what the
corner alignment takes up from the last frame's outline. The autopilot's attitude, read
at both frames' capture times, says how the camera turned; a turn alone moves the image by
the homography ``K R K^-1`` whatever the scene's depth (the vehicle's translation in a
frame's time is left to the trackers). :class:`TurnPredictor` gives that homography when
the turn is large enough to matter, for the corner alignment to start from
(:meth:`companion.corners.Corners.follow`).
"""

from __future__ import annotations

import math

import numpy as np

from tracker.camera import CameraModel
from tracker.geometry import FloatArray, rotation_from_rpy
from tracker.pose.types import AttitudeSample


def camera_turn(camera: CameraModel, before: AttitudeSample, after: AttitudeSample
                ) -> tuple[FloatArray, float]:
    """The camera's rotation from attitude ``before`` to ``after`` (directions in camera
    ``before`` -> camera ``after``) and its angle (deg)."""
    r0 = rotation_from_rpy(before.roll_rad, before.pitch_rad, before.yaw_rad) @ camera.r_body_cam
    r1 = rotation_from_rpy(after.roll_rad, after.pitch_rad, after.yaw_rad) @ camera.r_body_cam
    turn = r1.T @ r0
    angle = math.degrees(math.acos(max(-1.0, min(1.0, (float(np.trace(turn)) - 1.0) / 2.0))))
    return turn, angle


def turn_homography(camera: CameraModel, turn: FloatArray) -> FloatArray:
    """The homography taking the image before a pure rotation ``turn`` of the camera to the
    image after it: ``K R K^-1``."""
    k = camera.matrix
    h = k @ turn @ np.linalg.inv(k)
    return np.asarray(h / h[2, 2], np.float64)


class TurnPredictor:
    """The image's motion from the last frame's attitude to this one's, when the camera
    turned by ``min_turn_deg`` or more (else None: the alignment's own reach)."""

    def __init__(self, camera: CameraModel, min_turn_deg: float) -> None:
        self.camera = camera
        self.min_turn_deg = min_turn_deg
        self._last: AttitudeSample | None = None

    @property
    def enabled(self) -> bool:
        """False with ``min_turn_deg`` 0: :meth:`motion` is always None (nothing to read)."""
        return self.min_turn_deg > 0.0

    def motion(self, attitude: AttitudeSample | None) -> FloatArray | None:
        """This frame's attitude in; the homography from the last frame's image, or None
        (no attitude on either frame, a turn too small, or the prediction off)."""
        last, self._last = self._last, attitude
        if not self.enabled or last is None or attitude is None:
            return None
        turn, angle = camera_turn(self.camera, last, attitude)
        return turn_homography(self.camera, turn) if angle >= self.min_turn_deg else None
