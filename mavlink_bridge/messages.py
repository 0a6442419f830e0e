"""Input values of the bridge and the pure functions that turn them into MAVLink fields.

Nothing here does I/O.  The functions return plain tuples/dicts of field values that both
backends use, so the rules (frames, units, what "unknown" looks like) live in one place.

Frames: positions are NED metres in the local frame of the configured EKF origin; attitude is
ZYX Euler (``R_ned_body = Rz(yaw) Ry(pitch) Rx(roll)``), body FRD.  Times are microseconds of
the companion's monotonic clock, the same clock the link uses to answer TIMESYNC.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

Profile = Literal["ardupilot", "px4"]

# MAVLink enum values used here (common.xml).
MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_BODY_FRD = 12
MAV_FRAME_LOCAL_FRD = 20
MAV_ESTIMATOR_TYPE_VISION = 2
LANDING_TARGET_TYPE_VISION_FIDUCIAL = 2

UPPER_TRIANGLE_LEN = 21  # 6x6 symmetric matrix, row-major upper right triangle
_IU = np.triu_indices(6)


@dataclass(frozen=True)
class VisionFix:
    """A vehicle pose fix from vision, as the application hands it to the bridge.

    ``covariance`` is a 6x6 matrix (x, y, z, roll, pitch, yaw; m^2, rad^2) or its 21-element
    row-major upper triangle.  ``quality_percent`` 0..100 (ODOMETRY only; VPE has none).
    ``reset_counter`` must be bumped on a deliberate jump or re-localisation: the EKF then
    resets to the new position instead of rejecting it.
    """

    time_us: int
    position_ned_m: tuple[float, float, float]
    attitude_rpy_rad: tuple[float, float, float]
    covariance: tuple[float, ...]
    quality_percent: int = 100
    reset_counter: int = 0
    velocity_ned_m_s: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class LandingTargetFix:
    """Where the designated landing landmark is.

    ``offset_body_frd_m``: from the vehicle to the target in body FRD (ArduPilot).
    ``position_ned_m``: the target in the local NED frame of the origin (PX4).
    ``size_rad``: angular size (x, y) in the image, 0 if unknown.
    """

    time_us: int
    offset_body_frd_m: tuple[float, float, float]
    position_ned_m: tuple[float, float, float]
    target_num: int = 0
    size_rad: tuple[float, float] = (0.0, 0.0)


def upper_triangle(cov: Sequence[float] | np.ndarray) -> list[float]:
    """6x6 matrix or 21 values -> the 21-element row-major upper triangle (MAVLink order)."""
    a = np.asarray(cov, dtype=float)
    if a.shape == (6, 6):
        return [float(v) for v in a[_IU]]
    if a.shape == (UPPER_TRIANGLE_LEN,):
        return [float(v) for v in a]
    raise ValueError(f"covariance: expected a 6x6 matrix or 21 values, got shape {a.shape}")


def euler_to_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """ZYX Euler -> quaternion (w, x, y, z) rotating body FRD into the local frame.

    q = qz(yaw) * qy(pitch) * qx(roll)
    """
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def ned_to_body(v_ned: Sequence[float], roll: float, pitch: float, yaw: float) -> list[float]:
    """v_body = R_ned_body^T v_ned with R_ned_body = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    r = (
        (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        (-sp, cp * sr, cp * cr),
    )
    return [sum(r[i][j] * v_ned[i] for i in range(3)) for j in range(3)]


def fix_problem(fix: VisionFix, now_us: int, max_age_us: int) -> str | None:
    """Why ``fix`` must not be sent (``None`` when it is fine): stale, future, non-finite."""
    age = now_us - fix.time_us
    if age > max_age_us:
        return "stale"
    if age < -max_age_us:
        return "future"
    values = [*fix.position_ned_m, *fix.attitude_rpy_rad]
    if fix.velocity_ned_m_s is not None:
        values.extend(fix.velocity_ned_m_s)
    if not all(math.isfinite(v) for v in values):
        return "non_finite"
    try:
        cov = upper_triangle(fix.covariance)
    except ValueError:
        return "bad_covariance"
    if not all(math.isfinite(v) for v in cov) or min(cov[0], cov[6], cov[11]) < 0.0:
        return "bad_covariance"
    if not 0 <= fix.quality_percent <= 100:
        return "bad_quality"
    return None


def vpe_fields(fix: VisionFix) -> dict[str, Any]:
    """VISION_POSITION_ESTIMATE fields (ArduPilot and PX4 both read it as an NED pose)."""
    x, y, z = fix.position_ned_m
    roll, pitch, yaw = fix.attitude_rpy_rad
    return {
        "usec": fix.time_us, "x": x, "y": y, "z": z,
        "roll": roll, "pitch": pitch, "yaw": yaw,
        "covariance": upper_triangle(fix.covariance),
        "reset_counter": fix.reset_counter & 0xFF,
    }


def odometry_fields(fix: VisionFix, profile: Profile) -> dict[str, Any]:
    """ODOMETRY fields per profile.

    ArduPilot: frame_id LOCAL_FRD (20) and child_frame_id BODY_FRD (12) exactly, otherwise it
    drops the message; velocity in body FRD.  PX4: frame_id LOCAL_NED, child BODY_FRD,
    estimator_type VISION (MOCAP would go to a topic EKF2 never reads).

    Unknown velocity: PX4 reads NaN velocity as "not provided", so NaN (and NaN in the first
    velocity-covariance element, MAVLink's "unknown" marker) is sent; ArduPilot ignores the
    covariance and would fuse whatever numbers arrive, so it gets zeros and the deployer keeps
    ``EK3_SRC1_VELXY/VELZ = 0`` (docs/mavlink.md).
    """
    roll, pitch, yaw = fix.attitude_rpy_rad
    vel_cov = [0.0] * UPPER_TRIANGLE_LEN
    if fix.velocity_ned_m_s is not None:
        vel = ned_to_body(fix.velocity_ned_m_s, roll, pitch, yaw)
        pos_cov = upper_triangle(fix.covariance)
        vel_cov[0] = vel_cov[6] = vel_cov[11] = max(pos_cov[0], pos_cov[6], pos_cov[11])
    elif profile == "px4":
        vel = [math.nan] * 3
        vel_cov[0] = math.nan
    else:
        vel = [0.0, 0.0, 0.0]
    x, y, z = fix.position_ned_m
    return {
        "time_usec": fix.time_us,
        "frame_id": MAV_FRAME_LOCAL_FRD if profile == "ardupilot" else MAV_FRAME_LOCAL_NED,
        "child_frame_id": MAV_FRAME_BODY_FRD,
        "x": x, "y": y, "z": z,
        "q": list(euler_to_quaternion(roll, pitch, yaw)),
        "vx": vel[0], "vy": vel[1], "vz": vel[2],
        "rollspeed": 0.0, "pitchspeed": 0.0, "yawspeed": 0.0,
        "pose_covariance": upper_triangle(fix.covariance),
        "velocity_covariance": vel_cov,
        "reset_counter": fix.reset_counter & 0xFF,
        "estimator_type": MAV_ESTIMATOR_TYPE_VISION,
        "quality": int(fix.quality_percent),
    }


def landing_target_fields(lt: LandingTargetFix, profile: Profile) -> dict[str, Any] | None:
    """LANDING_TARGET fields per profile; ``None`` when the geometry is unusable.

    ArduPilot: frame BODY_FRD, x/y/z the body offset, distance = |offset| > 0, and
    angle_x = atan2(right, down), angle_y = -atan2(forward, down) (its autotest's convention).
    PX4: frame LOCAL_NED with the target's absolute position and position_valid = 1.
    """
    values = [*lt.offset_body_frd_m, *lt.position_ned_m, *lt.size_rad]
    if not all(math.isfinite(v) for v in values):
        return None
    fwd, right, down = lt.offset_body_frd_m
    distance = math.sqrt(fwd * fwd + right * right + down * down)
    if distance <= 0.0:
        return None
    if profile == "ardupilot":
        frame, (x, y, z) = MAV_FRAME_BODY_FRD, lt.offset_body_frd_m
    else:
        frame, (x, y, z) = MAV_FRAME_LOCAL_NED, lt.position_ned_m
    return {
        "time_usec": lt.time_us, "target_num": lt.target_num, "frame": frame,
        "angle_x": math.atan2(right, down), "angle_y": -math.atan2(fwd, down),
        "distance": distance, "size_x": lt.size_rad[0], "size_y": lt.size_rad[1],
        "x": x, "y": y, "z": z, "q": [1.0, 0.0, 0.0, 0.0],
        "type": LANDING_TARGET_TYPE_VISION_FIDUCIAL, "position_valid": 1,
    }
