"""Configuration of the pose solver (one frozen dataclass, every field defaulted)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class AssociationConfig:
    """Gates for naming unlabelled detections from a predicted pose."""

    #: Mahalanobis gate on the predicted-vs-observed centre (chi-square, 2 DOF, 99 %).
    gate_chi2: float = field(default=9.21, metadata={"gt": 0})
    #: Largest accepted log ratio between observed and predicted box size.
    max_log_size_ratio: float = field(default=0.7, metadata={"gt": 0})
    #: Largest accepted Bhattacharyya distance between appearance signatures.
    max_appearance_distance: float = field(default=0.5, metadata={"gt": 0, "le": 1})
    #: A candidate whose cost is within this of the best makes the match ambiguous.
    ambiguity_margin: float = field(default=2.0, metadata={"ge": 0})
    #: Weight of the appearance distance in the association cost.
    appearance_weight: float = field(default=20.0, metadata={"ge": 0})
    #: Landmarks predicted further than this outside the image are not candidates.
    image_margin_px: float = field(default=50.0, metadata={"ge": 0})


@dataclass(frozen=True)
class PoseConfig:
    """Pose-from-landmarks settings (section ``[pose]``)."""

    #: 1-sigma pixel noise of a corner or centre measurement.
    pixel_sigma_px: float = field(default=1.0, metadata={"gt": 0})
    #: Extra 1-sigma for a box centre used as the landmark centre (perspective bias).
    centre_sigma_px: float = field(default=2.0, metadata={"gt": 0})
    #: RANSAC inlier threshold (reprojection error, px).
    ransac_threshold_px: float = field(default=8.0, metadata={"gt": 0})
    ransac_iterations: int = field(default=100, metadata={"ge": 1})
    ransac_confidence: float = field(default=0.99, metadata={"gt": 0, "lt": 1})
    #: A landmark whose normalised reprojection error squared exceeds this per point is an
    #: outlier (chi-square, 2 DOF, 99.9 %).
    outlier_chi2_per_point: float = field(default=13.8, metadata={"gt": 0})
    #: Observations below this detector confidence are not used.
    min_confidence: float = field(default=0.3, metadata={"ge": 0, "le": 1})
    #: Image points spanning less than this (px) are degenerate.
    min_point_spread_px: float = field(default=3.0, metadata={"gt": 0})
    #: A range finder (DISTANCE_SENSOR) is fitted: the companion asks the autopilot for it.
    rangefinder: bool = False
    #: Attitude, altitude and range samples older than this (vs the frame) are ignored.
    max_sample_age_s: float = field(default=0.1, metadata={"gt": 0})
    #: Gauss-Newton iterations of the final refinement.
    max_iterations: int = field(default=10, metadata={"ge": 1})
    #: Largest accepted condition number of the normal matrix (degenerate geometry).
    max_condition: float = field(default=1e12, metadata={"gt": 1})
    #: Fixes with a position 1-sigma (largest axis) above this are refused.
    max_position_sigma_m: float = field(default=50.0, metadata={"gt": 0})
    #: Position 1-sigma giving quality 50 (quality = 100 * inlier ratio * exp(-ln2 s/ref)).
    quality_sigma_ref_m: float = field(default=1.0, metadata={"gt": 0})
    association: AssociationConfig = field(default_factory=AssociationConfig)
