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
    #: Attitude, altitude and range samples older than this (vs the frame) are ignored.
    max_sample_age_s: float = field(default=0.1, metadata={"gt": 0})
    #: 1-sigma of the autopilot's roll and pitch, and of its yaw, when it does not report
    #: its own (ArduPilot never does; docs/decisions.md, "An honest attitude prior").  The
    #: autopilot's attitude is itself estimated from our fixes: a few degrees, not tenths.
    attitude_roll_pitch_sigma_deg: float = field(default=2.5, metadata={"gt": 0})
    attitude_yaw_sigma_deg: float = field(default=5.0, metadata={"gt": 0})
    #: Check the autopilot's attitude against the landmarks' own whenever they fix the pose
    #: without it, and drop it for the fix when they disagree (off: trusted as stated).
    check_attitude: bool = True
    #: ... they disagree when adding the attitude prior raises the fix's chi-square by more
    #: than this (3 DOF, 99.9 %).
    attitude_gate_chi2: float = field(default=16.27, metadata={"gt": 0})
    #: ... and the companion drops it only when they disagree on this many solved frames in
    #: a row (each within 0.2 s of the last); the frames before give no fix.  One frame's
    #: disagreement is mostly the landmarks' (a plate's corners off for a frame, a cut plate
    #: taken for its mirror pose: 44 deg of pitch, 1.8 m off at a stated 7 cm, in the strict
    #: square); one that lasts is the autopilot's (docs/decisions.md, "A disagreement with
    #: the autopilot's attitude must repeat").  1: dropped at once.
    attitude_reject_frames: int = field(default=3, metadata={"ge": 1})
    #: Learn the autopilot's attitude error from the fixes that fix the attitude and correct
    #: the next frames' attitude by it (tracker/pose/attitude_bias.py); its 1-sigma grows by
    #: a random walk of these deg/sqrt(s) (roll/pitch, yaw: an EKF's error wanders by about
    #: its sigma over its correlation time, sqrt(2 sigma^2 / tau): 1 deg over 20 s, 3 deg
    #: over 120 s, mavlink_bridge/fake_drift.py) and is floored at these degrees (frames'
    #: pixel errors are correlated: a long stare at one plate is not many measurements).
    #: Off by default: offline it cut the survey's RMSE 3x, in the real-time demo it gained
    #: nothing and its NEES fell from 1.0 to 0.73 inside (docs/pose.md, "Learning the
    #: autopilot's attitude error").
    learn_attitude_bias: bool = False
    attitude_bias_walk_rp_deg_rt_s: float = field(default=0.3, metadata={"gt": 0})
    attitude_bias_walk_yaw_deg_rt_s: float = field(default=0.4, metadata={"gt": 0})
    attitude_bias_floor_rp_deg: float = field(default=0.2, metadata={"gt": 0})
    attitude_bias_floor_yaw_deg: float = field(default=0.5, metadata={"gt": 0})
    #: The learnt attitude's floors when it is the prior of a lone plate's fix (one plate
    #: with corners: its tilt and yaw come mostly from that prior); 0: the floors above.
    #: The floors above guard a fix of several plates against the error those plates taught
    #: the estimate a frame before (counted twice); a lone plate's prior was taught mostly
    #: by others, so only how well the estimate is known counts (docs/decisions.md, "The
    #: learnt attitude's floor for a lone plate").
    attitude_bias_lone_floor_rp_deg: float = field(default=0.0, metadata={"ge": 0})
    attitude_bias_lone_floor_yaw_deg: float = field(default=0.0, metadata={"ge": 0})
    #: 1-sigma of the autopilot's height (LOCAL_POSITION_NED down) as a prior.
    altitude_sigma_m: float = field(default=0.5, metadata={"gt": 0})
    #: Use the autopilot's height (LOCAL_POSITION_NED down) as a prior.
    use_altitude: bool = True
    #: Use the autopilot's range finder (DISTANCE_SENSOR): a laser that meets a landmark's
    #: face gives the distance to it.
    rangefinder: bool = False
    #: 1-sigma of a range finder reading.
    rangefinder_sigma_m: float = field(default=0.05, metadata={"gt": 0})
    #: One landmark seen without corners: its box's size on screen gives the distance to
    #: it (``f * size / pixels``, the less foreshortened side), with this 1-sigma relative
    #: to the distance (0: not used).  A tracker's box is not the plate's outline (its
    #: centre is off by 1.5-4.4 px, docs/pose.md): a fifth, cautious.
    box_size_sigma_rel: float = field(default=0.2, metadata={"ge": 0})
    #: A fix from one plate's corners alone: the outline's common scale and perspective
    #: (keystone) errors, which one plate cannot average out, get a 1-sigma of this times
    #: the corners' sigma each (0: the corners are independent).  The alignment moves an
    #: outline as a whole; its perspective decides the plate's tilt, and was measured
    #: 0.6-5.5 x the corner sigma (docs/pose.md, "One plate's outline").
    one_plate_outline_sigma_rel: float = field(default=0.0, metadata={"ge": 0})
    #: The same for one mode alone, if larger: the keystone along the image's height (the
    #: perspective that decides a wall plate's tilt towards the camera, and so where on the
    #: sphere about the plate the camera sits).  Measured 7.7 x the corner sigma on wall-01
    #: of the square flight's hover (a 0.9 px bias that ECC's own fit puts at 0.07 px),
    #: 5.5 x on wall-04, 0.8-1.3 x on survey and street (docs/decisions.md, "A lone plate's
    #: tilt").  0: the plate's own keystone is trusted as the corners' sigma says.
    one_plate_tilt_sigma_rel: float = field(default=0.0, metadata={"ge": 0})
    #: A plate's corner errors along its outline's eight modes (shift across, down,
    #: rotation, scale, aspect, shear, perspective across, along:
    #: ``tracker.pose.inputs.outline_basis``), each as a multiple of the corners' sigma.
    #: All 1: the four corners' errors are independent (the same sigma in every mode).
    #: An alignment moves an outline as a whole, so a camera's corners may err more in
    #: some modes (scale, tilt) than in others (rotation); measured per camera with
    #: ``benchmarks/corner_errors.py`` (docs/pose.md, "A plate's corners err together").
    corner_mode_sigma_rel: tuple[float, float, float, float, float, float, float, float] = \
        field(default=(1.0,) * 8, metadata={"gt": 0})
    #: Gauss-Newton iterations of the final refinement.
    max_iterations: int = field(default=10, metadata={"ge": 1})
    #: Largest accepted condition number of the normal matrix (degenerate geometry).
    max_condition: float = field(default=1e12, metadata={"gt": 1})
    #: Fixes with a position 1-sigma (largest axis) above this are refused.
    max_position_sigma_m: float = field(default=50.0, metadata={"gt": 0})
    #: Position 1-sigma giving quality 50 (quality = 100 * inlier ratio * exp(-ln2 s/ref)).
    quality_sigma_ref_m: float = field(default=1.0, metadata={"gt": 0})
    association: AssociationConfig = field(default_factory=AssociationConfig)
