"""What the pose solver works with: landmarks in view as point groups, and the priors.

:func:`make_groups` turns the named observations into one :class:`Group` of image points per
landmark (its four corners when known, else its centre); :func:`make_priors` gathers the
autopilot's attitude and altitude, the laser meeting a landmark's face (:func:`laser_for`)
and, for one landmark seen without corners, the distance its box's size gives
(:func:`size_if_needed`).  Used by :mod:`tracker.pose.solve`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache

import cv2
import numpy as np
import numpy.typing as npt

from tracker.camera import CameraModel
from tracker.geometry import FloatArray, rotation_from_rpy
from tracker.pose.config import PoseConfig
from tracker.pose.landmarks import face_rotation, landmark_corners_ned, landmark_normal_ned
from tracker.pose.refine import DistancePrior, PointSet, Priors, RangePrior
from tracker.pose.types import (
    AltitudeSample,
    AttitudeSample,
    MapLandmark,
    Observation,
    RangeSample,
)

BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Group:
    """One landmark in view with its observation and its image points."""

    landmark: MapLandmark
    observation: Observation
    points_ned: FloatArray
    pixels_distorted: FloatArray
    pixels_ideal: FloatArray
    sigma_px: float
    #: the unit offsets of the points from their centre (k x 2) and beta of the plate's
    #: common scale error (see refine.PointSet); beta 0: none
    scale_dir: FloatArray | None = None
    scale_beta: float = 0.0
    #: 1-sigma (px) of the outline's common scale and perspective when this plate's corners
    #: are all the fix has (``PoseConfig.one_plate_outline_sigma_rel``; see :func:`point_set`)
    outline_sigma_px: float = 0.0
    #: 1-sigma (px) of its keystone along the image's height (the plate's tilt towards the
    #: camera) when its corners are all the fix has, if larger (``one_plate_tilt_sigma_rel``)
    tilt_sigma_px: float = 0.0
    #: each outline mode's 1-sigma over ``sigma_px`` when the plate's four corners are
    #: measured and they are not all 1 (``PoseConfig.corner_mode_sigma_rel``), else None
    mode_rel: FloatArray | None = None
    #: each point's 1-sigma (px) when they differ (a cut plate's extrapolated corners,
    #: ``Observation.extrapolated_sigma_px``); None: ``sigma_px`` for every point
    point_sigmas_px: FloatArray | None = None

    @cached_property
    def outline_basis(self) -> FloatArray:
        """:func:`outline_basis` of its ideal pixels, once: a solve stacks the same groups
        several times (the robust solve, the attitude check, the consistency check)."""
        return outline_basis(self.pixels_ideal)


@dataclass(frozen=True)
class Context:
    """Everything that stays fixed while landmarks are dropped."""

    camera: CameraModel
    k: FloatArray
    dist: FloatArray
    r_body_cam: FloatArray
    config: PoseConfig
    attitude: AttitudeSample | None
    altitude: AltitudeSample | None
    laser: RangeSample | None
    distorted: bool  # does the camera have any distortion to undo?


@lru_cache(maxsize=16)
def camera_arrays(camera: CameraModel) -> tuple[FloatArray, FloatArray, FloatArray]:
    """K, distortion and R_body_cam of a camera (computed once per camera model).

    No distortion at all gives an empty array: OpenCV then skips undistorting.
    """
    dist = camera.dist_coeffs
    arrays = (camera.matrix, dist if np.any(dist) else np.empty(0), camera.r_body_cam)
    for a in arrays:
        a.setflags(write=False)
    return arrays


#: The end of the note on a landmark that several observations claimed (all left out).
CLAIM_CONFLICT = "not used"


def make_groups(
    ctx: Context,
    observations: Sequence[Observation],
    named: list[tuple[int, MapLandmark]],
    notes: list[str],
) -> list[Group]:
    """Image points per landmark (corners when known, else the centre); one per landmark."""
    claims: dict[str, list[int]] = {}
    for i, lm in named:
        claims.setdefault(lm.landmark_id, []).append(i)
    best: dict[str, tuple[int, MapLandmark]] = {}
    for i, lm in named:
        who = claims[lm.landmark_id]
        if len(who) == 1:
            best[lm.landmark_id] = (i, lm)
        elif i == who[0]:  # one landmark, several detections: at least one is misnamed
            notes.append(f"landmark {lm.landmark_id!r} claimed by observations {who}: "
                         f"{CLAIM_CONFLICT}")
    cfg = ctx.config
    centre_sigma = math.hypot(cfg.pixel_sigma_px, cfg.centre_sigma_px)
    modes = np.asarray(cfg.corner_mode_sigma_rel, dtype=np.float64)
    groups = []
    for i, lm in best.values():
        obs = observations[i]
        each = None
        if obs.corners_px is not None:
            measured = np.array(obs.corners_measured or (True,) * 4)  # cut by the edge: some
            sig = cfg.pixel_sigma_px if obs.corner_sigma_px is None else obs.corner_sigma_px
            if obs.extrapolated_sigma_px is not None:  # the rest as weak points
                each = np.where(measured, sig, max(sig, obs.extrapolated_sigma_px))
                measured = np.ones(4, dtype=bool)
            pts = landmark_corners_ned(lm)[measured]
            px = np.array(obs.corners_px, dtype=np.float64)[measured]
        else:
            pts, sig = np.array([lm.position_ned_m], dtype=np.float64), centre_sigma
            px = np.array([obs.centre_px], dtype=np.float64)
        ideal = _undistort(ctx, px) if ctx.distorted else px
        # a whole outline's common errors; a cut one's measured corners are points
        scale = obs.corner_scale_sigma_px if obs.all_corners else None
        rel = (cfg.one_plate_outline_sigma_rel, cfg.one_plate_tilt_sigma_rel)
        outline, tilt = (r * sig if obs.all_corners else 0.0 for r in rel)
        stated = modes if obs.corner_mode_sigma_rel is None else \
            np.asarray(obs.corner_mode_sigma_rel, dtype=np.float64)
        # all 1: the corners are independent
        mode_rel = stated if obs.all_corners and bool(np.any(stated != 1.0)) else None
        groups.append(Group(lm, obs, pts, px, ideal, sig, *_scale_error(ideal, sig, scale),
                            outline, tilt, mode_rel, each))
    return groups


def _scale_error(
    corners: FloatArray, sigma: float, width_sigma: float | None
) -> tuple[FloatArray | None, float]:
    """Unit offsets of the corners from their centre and ``beta`` for a common scale error
    of ``width_sigma`` px in the plate's width (``Sigma = sigma^2 I + (s / w)^2 u u^T``)."""
    if not width_sigma:
        return None, 0.0
    c = corners.tolist()
    cu, cv = sum(p[0] for p in c) / len(c), sum(p[1] for p in c) / len(c)
    norm = math.sqrt(sum((p[0] - cu) ** 2 + (p[1] - cv) ** 2 for p in c))
    width = 0.5 * (math.dist(c[1], c[0]) + math.dist(c[2], c[3]))
    if norm <= 0.0 or width <= 0.0:
        return None, 0.0
    a_uu = (width_sigma / width) ** 2 * norm**2
    u = (corners - (cu, cv)) / norm
    return u, 1.0 - sigma / math.sqrt(sigma**2 + a_uu)


def _undistort(ctx: Context, px: FloatArray) -> FloatArray:
    """Distorted -> ideal pinhole pixels (same K)."""
    out = cv2.undistortPoints(px.reshape(-1, 1, 2), ctx.k, ctx.dist, P=ctx.k)
    return np.asarray(out.reshape(-1, 2), dtype=np.float64)


def outline_basis(corners: FloatArray) -> FloatArray:
    """An outline's orthonormal modes over its 2k corner coordinates (rows x, y of each
    corner in turn), columns: shift across, shift down, rotation, scale about its centre,
    aspect, shear, perspective across, along (Gram-Schmidt in that order)."""
    d = corners - corners.mean(axis=0)
    x, y = d[:, 0], d[:, 1]
    basis = np.zeros((2 * len(d), 8))
    across, down = basis[0::2], basis[1::2]  # each corner's x row, then its y row
    across[:, 0] = 1.0
    down[:, 1] = 1.0
    across[:, 2], down[:, 2] = -y, x
    across[:, 3], down[:, 3] = x, y
    across[:, 4], down[:, 4] = x, -y
    across[:, 5], down[:, 5] = y, x
    across[:, 6], down[:, 6] = x * x, x * y
    across[:, 7], down[:, 7] = x * y, y * y
    return np.asarray(np.linalg.qr(basis)[0], dtype=np.float64)


def _outline_modes(g: Group, lone: bool) -> tuple[FloatArray, FloatArray]:
    """A plate's outline modes (k x 2 x 8, :func:`outline_basis`) and their betas (8,): each
    mode's variance is the corners' ``(sigma * mode_rel)**2``, the scale's plus the
    declared width error's (``scale_beta``).  A lone plate (its corners all the fix has)
    keeps ``sigma**2`` in every mode, adds ``outline_sigma_px**2`` to each from the scale
    on, and its keystone along the height has at least ``tilt_sigma_px**2`` there: one
    plate cannot average them out, and with smaller modes its corners outweigh the
    attitude prior (docs/pose.md, "A plate's corners err together")."""
    q = g.outline_basis
    sig = g.sigma_px
    var = np.full(8, sig**2) if g.mode_rel is None or lone else sig**2 * g.mode_rel**2
    if g.scale_beta > 0.0:  # beta = 1 - sigma / sqrt(sigma^2 + a): a back from beta
        var[3] += sig**2 * ((1.0 / (1.0 - g.scale_beta)) ** 2 - 1.0)
    if lone:
        var[3:] += g.outline_sigma_px**2
        var[7] = max(var[7], sig**2 + g.tilt_sigma_px**2)
    return q.reshape(-1, 2, 8), 1.0 - sig / np.sqrt(var)


def point_set(groups: list[Group]) -> PointSet:
    """Stack every landmark's points for the refinement.  A plate's four corners share the
    errors of its outline's modes (:func:`_outline_modes`) when a mode is stated apart
    from the corners: its width error, ``mode_rel`` when the fix has other landmarks, and
    one plate alone its outline's."""
    counts = [g.points_ned.shape[0] for g in groups]
    lone = len(groups) == 1 and groups[0].observation.all_corners and \
        max(groups[0].outline_sigma_px, groups[0].tilt_sigma_px) > 0.0
    scale_dir = scale_beta = None
    if lone or (len(groups) > 1 and any(g.mode_rel is not None for g in groups)):
        modes = [_outline_modes(g, lone) if g.observation.all_corners
                 else (np.zeros((n, 2, 8)), np.zeros(8))
                 for g, n in zip(groups, counts, strict=True)]
        scale_dir = np.concatenate([d for d, _ in modes])
        scale_beta = np.vstack([np.tile(b, (n, 1))
                                for (_, b), n in zip(modes, counts, strict=True)])
    elif any(g.scale_beta > 0.0 for g in groups):
        scale_dir = np.vstack([np.zeros((n, 2)) if g.scale_dir is None else g.scale_dir
                               for g, n in zip(groups, counts, strict=True)])
        scale_beta = np.repeat([g.scale_beta for g in groups], counts)
    return PointSet(
        np.vstack([g.points_ned for g in groups]),
        np.vstack([g.pixels_ideal for g in groups]),
        np.concatenate([np.full(n, g.sigma_px) if g.point_sigmas_px is None
                        else g.point_sigmas_px for g, n in zip(groups, counts, strict=True)]),
        np.repeat(np.arange(len(groups), dtype=np.int64), counts),
        scale_dir,
        scale_beta,
    )


def firm_points(groups: list[Group]) -> BoolArray:
    """Which of :func:`point_set`'s points are measured, not extrapolated (a cut plate's
    corners out of the image, ``Group.point_sigmas_px``): a linear start rests on those,
    the refinement weighs them all."""
    return np.concatenate([np.ones(g.points_ned.shape[0], dtype=bool)
                           if g.point_sigmas_px is None else g.point_sigmas_px <= g.sigma_px
                           for g in groups])


def make_priors(
    ctx: Context, laser: RangePrior | None, distance: DistancePrior | None = None
) -> Priors:
    """Autopilot attitude and altitude (when fresh), the laser and a box's size, as
    refinement priors."""
    att_rpy = att_sig = None
    if ctx.attitude is not None:
        a = ctx.attitude
        att_rpy = np.array([a.roll_rad, a.pitch_rad, a.yaw_rad])
        att_sig = np.array([a.roll_pitch_sigma_rad, a.roll_pitch_sigma_rad, a.yaw_sigma_rad])
    alt = ctx.altitude
    return Priors(
        att_rpy,
        att_sig,
        None if alt is None else alt.down_m,
        0.1 if alt is None else alt.sigma_m,
        laser,
        distance,
    )


def size_if_needed(
    ctx: Context, g: Group, bearing: FloatArray, laser: RangePrior | None
) -> DistancePrior | None:
    """The box-size distance to the one landmark in view when neither the laser nor the
    altitude fixes its distance better: the altitude fixes it to ``sigma / |b_down|``,
    poorly for a landmark near the camera's height (a nearly level bearing ``b``).  The
    size is a coarse measure (a box is not the plate's outline), used only where needed."""
    if g.observation.corners_px is not None:
        return None  # a plate cut by the image's edge: its box is not its size
    size = _size_distance(ctx, g)
    if size is None or laser is not None:
        return None
    alt = ctx.altitude
    if alt is not None and alt.sigma_m <= size.sigma_m * abs(float(bearing[2])):
        return None
    return size


def _size_distance(ctx: Context, g: Group) -> DistancePrior | None:
    """The distance to a landmark from its box's size on screen: ``f * size / pixels`` for
    the side foreshortened least (the larger pixels per metre), 1-sigma
    ``box_size_sigma_rel`` of it; None when not configured or the box has no size."""
    rel = ctx.config.box_size_sigma_rel
    lm, (w_px, h_px) = g.landmark, g.observation.box_wh_px
    px_per_m = max(w_px / lm.width_m, h_px / lm.height_m)
    if rel <= 0.0 or px_per_m <= 0.0:
        return None
    d = float(ctx.k[0, 0]) / px_per_m
    return DistancePrior(np.asarray(lm.position_ned_m, dtype=np.float64), d, rel * d)


def range_prior(ctx: Context, lm: MapLandmark) -> RangePrior | None:
    """The laser as meeting the plane of ``lm``."""
    if ctx.laser is None:
        return None
    axis = np.asarray(ctx.laser.axis_body, dtype=np.float64)
    return RangePrior(
        ctx.laser.distance_m,
        ctx.laser.sigma_m,
        axis / np.linalg.norm(axis),
        np.asarray(lm.position_ned_m, dtype=np.float64),
        landmark_normal_ned(lm),
    )


def laser_hits(rp: RangePrior, lm: MapLandmark, x: FloatArray) -> bool:
    """Does the beam from pose ``x`` meet the face of ``lm`` (half-size x 1.5 margin)?"""
    a = rotation_from_rpy(*x[3:]) @ rp.axis_body
    na = float(rp.plane_normal @ a)
    if abs(na) < 1e-6:
        return False
    t = float(rp.plane_normal @ (rp.plane_point - x[:3])) / na
    if t <= 0:
        return False
    hit_face = face_rotation(lm.facing_deg).T @ (x[:3] + t * a - rp.plane_point)
    return abs(hit_face[0]) <= 0.75 * lm.width_m and abs(hit_face[1]) <= 0.75 * lm.height_m


def laser_for(ctx: Context, groups: list[Group], x0: FloatArray) -> RangePrior | None:
    """The laser prior on the first landmark whose face the beam meets at ``x0``."""
    for g in groups:
        rp = range_prior(ctx, g.landmark)
        if rp is not None and laser_hits(rp, g.landmark, x0):
            return rp
    return None
