"""Position fix from landmarks: association, robust pose solving and honest covariance.

Pure numpy/OpenCV.  Entry points: :func:`solve_pose` (observations -> :class:`PoseFix` or
:class:`NoFix`) and :func:`associate` (name unlabelled detections from a predicted pose).
Frames and corner order: :mod:`tracker.pose.landmarks`; the maths: :mod:`tracker.pose.refine`.
"""

from tracker.pose.association import Ambiguity, Association, Match, associate
from tracker.pose.config import AssociationConfig, PoseConfig
from tracker.pose.landmarks import face_rotation, landmark_corners_ned, landmark_normal_ned
from tracker.pose.solve import solve_pose
from tracker.pose.types import (
    AltitudeSample,
    AttitudeSample,
    MapLandmark,
    NoFix,
    Observation,
    PoseFix,
    PosePrior,
    RangeSample,
    laser_axis_from_mav_orientation,
)

__all__ = [
    "AltitudeSample",
    "Ambiguity",
    "Association",
    "AssociationConfig",
    "AttitudeSample",
    "MapLandmark",
    "Match",
    "NoFix",
    "Observation",
    "PoseConfig",
    "PoseFix",
    "PosePrior",
    "RangeSample",
    "associate",
    "face_rotation",
    "landmark_corners_ned",
    "landmark_normal_ned",
    "laser_axis_from_mav_orientation",
    "solve_pose",
]
