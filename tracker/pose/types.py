"""Value types of the pose solver: what the camera saw, the map, side sensors and the fix.

All frozen dataclasses; units and frames in field names.  Pixel coordinates are the
distorted (raw) image coordinates the detector or tracker reports.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tracker.geometry import FloatArray

#: Solvers the pose module may choose (``PoseFix.solver``).
SOLVERS = (
    "ippe",
    "ippe_square",
    "pnp",
    "pnp_ransac",
    "bearing_ls",
    "range_bearing",
    "altitude_bearing",
    "size_bearing",
)
#: The solvers of a fix from one landmark's bearing (its centre or one corner) and a
#: distance (range finder, height, box size): weak across the bearing.
ONE_BEARING_SOLVERS = ("range_bearing", "altitude_bearing", "size_bearing")


@dataclass(frozen=True)
class Observation:
    """One detection or track of a landmark in one frame.

    ``landmark_id`` is ``None`` when only the ``category`` is known (a detector hit that
    association must name).  ``corners_px`` are the images of the landmark's four corners
    in the order of :func:`tracker.pose.landmarks.landmark_corners_ned` (top-left,
    top-right, bottom-right, bottom-left as seen from the front), when known.
    ``signature`` is an optional appearance descriptor (e.g. a normalised colour
    histogram) compared with :attr:`MapLandmark.signature` by the Bhattacharyya distance.
    ``corner_sigma_px``: the corners' own 1-sigma when the detector knows it (a small plate's
    corners are less certain than a big one's); None: the solver's ``pixel_sigma_px``.
    ``corner_scale_sigma_px``: 1-sigma of an error common to all four corners that scales the
    quadrilateral about its centre, given as the change of the plate's width in pixels (an
    alignment's outline is drawn in or out as a whole); None or 0: the corners' errors are
    independent.
    ``corners_measured``: which of the four corners were measured (a plate cut by the
    image's edge: the corners outside the image are only extrapolated, and are not
    observations); None: all four.  A partly measured plate gives its measured corners as
    points, without the outline's common errors.
    ``extrapolated_sigma_px``: with ``corners_measured``, the 1-sigma of the corners it leaves
    out, which then count as weak points (a cut plate's outline carried out of the image by
    its alignment on the part in view: they hold its scale and turn, which its measured
    corners alone do not); None: they are left out.
    ``corner_mode_sigma_rel``: the plate's outline modes over its corner sigma in a fix of
    several plates, when its perception states them; None: the solver's
    ``corner_mode_sigma_rel``.
    """

    centre_px: tuple[float, float]
    box_wh_px: tuple[float, float]
    confidence: float = 1.0
    landmark_id: str | None = None
    category: str | None = None
    corners_px: tuple[tuple[float, float], ...] | None = None
    frame_index: int = 0
    signature: tuple[float, ...] | None = None
    corner_sigma_px: float | None = None
    corner_scale_sigma_px: float | None = None
    corners_measured: tuple[bool, bool, bool, bool] | None = None
    extrapolated_sigma_px: float | None = None
    corner_mode_sigma_rel: tuple[float, ...] | None = None

    @property
    def all_corners(self) -> bool:
        """Four measured corners (a whole outline)?"""
        return self.corners_px is not None and (
            self.corners_measured is None or all(self.corners_measured))


@dataclass(frozen=True)
class MapLandmark:
    """A landmark of the practical map in local NED.

    ``facing_deg``: azimuth of the face's outward normal, degrees from north; ``None`` for a
    landmark lying flat, facing up (its top edge then points north).
    """

    landmark_id: str
    position_ned_m: tuple[float, float, float]
    width_m: float
    height_m: float
    facing_deg: float | None = None
    category: str = ""
    signature: tuple[float, ...] | None = None


@dataclass(frozen=True)
class AttitudeSample:
    """Vehicle attitude from the autopilot (ZYX Euler, body FRD in NED) with its 1-sigma.

    The defaults are ``PoseConfig``'s (2.5 deg roll/pitch, 5 deg yaw): the autopilot's
    estimate, itself fed by our fixes, is a prior to check, not a truth.
    """

    time_us: int
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    roll_pitch_sigma_rad: float = float(np.deg2rad(2.5))
    yaw_sigma_rad: float = float(np.deg2rad(5.0))


@dataclass(frozen=True)
class AltitudeSample:
    """Vehicle height as a NED down coordinate (m, local frame) with its 1-sigma."""

    time_us: int
    down_m: float
    sigma_m: float = 0.1


@dataclass(frozen=True)
class RangeSample:
    """A laser range along a fixed body axis (DISTANCE_SENSOR or a configured lidar).

    ``axis_body`` is the unit direction of the beam in body FRD, e.g. (0, 0, 1) for a
    downward rangefinder or (1, 0, 0) for a forward one.  The beam is assumed to hit the
    plane of the landmark it is associated with (the "semantic laser": the laser gives the
    distance, vision names the landmark).
    """

    time_us: int
    distance_m: float
    axis_body: tuple[float, float, float] = (0.0, 0.0, 1.0)
    sigma_m: float = 0.05


def laser_axis_from_mav_orientation(orientation: int) -> tuple[float, float, float]:
    """Beam direction in body FRD for a DISTANCE_SENSOR ``orientation`` (MAV_SENSOR_ORIENTATION).

    Supported: 0..7 (``MAV_SENSOR_ROTATION_YAW_45*k``: forward, then clockwise seen from
    above), 24 (``PITCH_90``: up) and 25 (``PITCH_270``: down).  The forward unit vector
    rotated by the named rotation.
    """
    if 0 <= orientation <= 7:
        yaw = np.deg2rad(45.0 * orientation)
        return (round(float(np.cos(yaw)), 12), round(float(np.sin(yaw)), 12), 0.0)
    if orientation == 24:
        return (0.0, 0.0, -1.0)
    if orientation == 25:
        return (0.0, 0.0, 1.0)
    raise ValueError(
        f"orientation: expected a MAV_SENSOR_ORIENTATION of 0..7, 24 or 25, got {orientation}"
    )


@dataclass(frozen=True)
class PosePrior:
    """A predicted vehicle pose (e.g. last fix propagated) used to associate detections."""

    position_ned_m: tuple[float, float, float]
    attitude_rpy_rad: tuple[float, float, float]
    position_sigma_m: float = 1.0
    attitude_sigma_rad: float = float(np.deg2rad(2.0))


@dataclass(frozen=True)
class PoseFix:
    """A vehicle position fix.

    ``covariance`` is 6x6 in the order x y z (NED, m) roll pitch yaw (rad).  ``quality`` is
    0..100 (MAVLink ODOMETRY convention, 100 = best).  ``reset_counter`` is carried for the
    caller, which owns it.  ``notes`` say which observations were dropped and why.
    """

    time_us: int
    position_ned_m: tuple[float, float, float]
    attitude_rpy_rad: tuple[float, float, float]
    covariance: FloatArray
    quality: int
    landmark_ids: tuple[str, ...]
    solver: str
    reset_counter: int = 0
    reprojection_rms_px: float = 0.0
    notes: tuple[str, ...] = field(default=())
    #: how the autopilot's attitude was used: "none" (no fresh sample), "used", or
    #: "rejected" (it disagreed with the landmarks' own attitude; the fix ignores it)
    attitude_prior: str = "none"
    #: whitened residual sum of squares at the solution (pixels and priors), chi-square
    chi2: float = 0.0
    #: the part of ``covariance`` carried by the autopilot's own attitude and height (6x6;
    #: None without them): its error comes back in every fix while it lasts, so a stream of
    #: such fixes is not independent (companion.fixgate states it so)
    echo_covariance: FloatArray | None = None
    #: the covariance the autopilot is sent (companion.fixgate's ``stated``: the autopilot's
    #: part counted once per correlation time); None: ``covariance`` itself.  ``covariance``
    #: stays this fix's own (its NEES, the reports)
    sent_covariance: FloatArray | None = None
    #: the position the autopilot is sent when it differs from ``position_ned_m``
    #: (companion.fixgate's ``stated``: a fix stated worse than the autopilot can fuse it,
    #: moved towards the autopilot's own estimate so that its pull is the stated one)
    sent_position_ned_m: tuple[float, float, float] | None = None

    @property
    def covariance_urt(self) -> tuple[float, ...]:
        """The 21 upper-right-triangle entries, row-major, as MAVLink VISION_POSITION_ESTIMATE
        and ODOMETRY expect them (first row 6 entries, then 5, ...; x y z roll pitch yaw)."""
        rows, cols = np.triu_indices(6)
        return tuple(float(v) for v in self.covariance[rows, cols])

    @property
    def autopilot_position(self) -> tuple[float, float, float]:
        """The position the autopilot is sent: ``sent_position_ned_m`` when set, else
        ``position_ned_m``."""
        return self.position_ned_m if self.sent_position_ned_m is None \
            else self.sent_position_ned_m

    @property
    def autopilot_covariance(self) -> FloatArray:
        """The covariance the autopilot is sent: ``sent_covariance`` when stated, else
        ``covariance``."""
        return self.covariance if self.sent_covariance is None else self.sent_covariance

    @property
    def position_sigma_m(self) -> tuple[float, float, float]:
        """1-sigma of north, east, down from the covariance diagonal."""
        d = np.sqrt(np.diag(self.covariance)[:3])
        return float(d[0]), float(d[1]), float(d[2])


@dataclass(frozen=True)
class NoFix:
    """No position fix this time, with a one-line reason."""

    time_us: int
    reason: str
    notes: tuple[str, ...] = field(default=())
    #: The landmark named as not fitting when too few were in play to drop it (three), else
    #: None: the tracks count it (``companion.tracks.TrackSet.drop_rejected``).
    outlier: str | None = None
