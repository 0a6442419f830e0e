"""A pure geometric flight simulator for the pose solver (tests and benchmarks).

Landmarks are planar rectangles in NED (:class:`MapLandmark`, corners per
:mod:`tracker.pose.landmarks`); the vehicle follows a scripted trajectory; corners and
centres are projected through :meth:`CameraModel.world_to_camera` and
:meth:`CameraModel.project_camera_points` and get Gaussian pixel noise.  The autopilot
attitude and altitude are the truth plus Gaussian noise; the laser is a ray cast against the
landmark faces plus Gaussian noise.  Everything is deterministic given the Generator.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from tracker.camera import CameraModel
from tracker.geometry import FloatArray, rotation_from_rpy
from tracker.pose.landmarks import face_rotation, landmark_corners_ned, landmark_normal_ned
from tracker.pose.types import (
    AltitudeSample,
    AttitudeSample,
    MapLandmark,
    Observation,
    RangeSample,
)

#: t (s) -> (position NED m, roll/pitch/yaw rad)
Trajectory = Callable[[float], tuple[FloatArray, tuple[float, float, float]]]


@dataclass(frozen=True)
class SensorNoise:
    """1-sigma noise of the simulated measurements.

    The corner sigma is what the perception delivers for plates the size the reference
    flights see (8-41 px wide): its corners on rendered frames measured 0.24-0.26 px RMS for
    plates 30-60 px wide (docs/pose.md, "Simulated flights"); 0.3 px is the round figure
    above that.  A box centre (no corners) stands for an unbiased landmark-centre
    measurement of 1 px; the tracker's boxes are worse (1.5-4.4 px RMS from the plates'
    centres, same page), so the centre-only flights are optimistic for them.
    """

    pixel_sigma_px: float = 0.3
    centre_sigma_px: float = 1.0
    roll_pitch_sigma_rad: float = float(np.deg2rad(0.1))
    yaw_sigma_rad: float = float(np.deg2rad(1.0))
    altitude_sigma_m: float = 0.1
    range_sigma_m: float = 0.03


@dataclass(frozen=True)
class SimFrame:
    """What one simulated frame gives the solver, and the truth."""

    time_us: int
    observations: tuple[Observation, ...]
    true_position_ned_m: FloatArray
    true_attitude_rpy_rad: tuple[float, float, float]
    attitude: AttitudeSample
    altitude: AltitudeSample
    laser: RangeSample | None = field(default=None)


def observe_landmark(
    landmark: MapLandmark,
    camera: CameraModel,
    position_ned_m: FloatArray,
    attitude_rpy_rad: tuple[float, float, float],
    rng: np.random.Generator,
    noise: SensorNoise,
    min_box_px: float = 8.0,
) -> Observation | None:
    """The noisy observation of ``landmark``, or ``None`` when it is not fully in view."""
    c = np.asarray(landmark.position_ned_m, dtype=np.float64)
    if float(landmark_normal_ned(landmark) @ (position_ned_m - c)) <= 0.0:
        return None
    pts = np.vstack([c, landmark_corners_ned(landmark)])
    xc = camera.world_to_camera(pts, position_ned_m, attitude_rpy_rad)
    if np.any(xc[:, 2] <= 0.1):
        return None
    uv = camera.project_camera_points(xc)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < camera.width) & (uv[:, 1] >= 0)
    if not np.all(inside & (uv[:, 1] < camera.height)):
        return None
    corners = uv[1:] + rng.normal(0.0, noise.pixel_sigma_px, size=(4, 2))
    centre = uv[0] + rng.normal(0.0, noise.centre_sigma_px, size=2)
    span = corners.max(axis=0) - corners.min(axis=0)
    if min(span) < min_box_px:
        return None
    return Observation(
        centre_px=(float(centre[0]), float(centre[1])),
        box_wh_px=(float(span[0]), float(span[1])),
        confidence=0.9,
        landmark_id=landmark.landmark_id,
        category=landmark.category,
        corners_px=tuple((float(u), float(v)) for u, v in corners),
        signature=landmark.signature,
    )


def cast_laser(
    landmarks: Sequence[MapLandmark],
    position_ned_m: FloatArray,
    attitude_rpy_rad: tuple[float, float, float],
    axis_body: tuple[float, float, float],
) -> float | None:
    """True distance along the beam to the nearest landmark face it meets, else ``None``."""
    a = rotation_from_rpy(*attitude_rpy_rad) @ np.asarray(axis_body, dtype=np.float64)
    best = None
    for lm in landmarks:
        n = landmark_normal_ned(lm)
        c = np.asarray(lm.position_ned_m, dtype=np.float64)
        na = float(n @ a)
        if abs(na) < 1e-9:
            continue
        t = float(n @ (c - position_ned_m)) / na  # ray meets plane n.(x - c) = 0
        hit = face_rotation(lm.facing_deg).T @ (position_ned_m + t * a - c)
        inside = abs(hit[0]) <= lm.width_m / 2 and abs(hit[1]) <= lm.height_m / 2
        if t > 0 and inside and (best is None or t < best):
            best = t
    return best


def simulate_frame(
    landmarks: Sequence[MapLandmark],
    camera: CameraModel,
    trajectory: Trajectory,
    t_s: float,
    rng: np.random.Generator,
    noise: SensorNoise,
    laser_axis_body: tuple[float, float, float] | None = None,
) -> SimFrame:
    """Observations, autopilot samples and laser of the frame at ``t_s``."""
    p, rpy = trajectory(t_s)
    t_us = round(t_s * 1e6)
    obs = [observe_landmark(lm, camera, p, rpy, rng, noise) for lm in landmarks]
    rp = noise.roll_pitch_sigma_rad
    att = np.asarray(rpy) + rng.normal(0.0, 1.0, 3) * np.array([rp, rp, noise.yaw_sigma_rad])
    attitude = AttitudeSample(
        t_us, float(att[0]), float(att[1]), float(att[2]), rp, noise.yaw_sigma_rad
    )
    altitude = AltitudeSample(
        t_us, float(p[2] + rng.normal(0.0, noise.altitude_sigma_m)), noise.altitude_sigma_m
    )
    laser = None
    if laser_axis_body is not None:
        d = cast_laser(landmarks, p, rpy, laser_axis_body)
        if d is not None:
            d_noisy = d + float(rng.normal(0.0, noise.range_sigma_m))
            laser = RangeSample(t_us, d_noisy, laser_axis_body, noise.range_sigma_m)
    return SimFrame(t_us, tuple(o for o in obs if o is not None), p, rpy, attitude, altitude, laser)
