"""From what the camera sees to where the vehicle is: :func:`solve_pose`.

Solver choice (automatic, see ``docs/pose.md``):

========================================  =====================  ==================
what is in view                           autopilot attitude      solver
========================================  =====================  ==================
one landmark with four corners            optional (picks flip)   ``ippe[_square]``
four or more points, two+ landmarks       absent                  ``pnp`` / ``pnp_ransac``
two or more landmarks (centres/corners)   present                 ``bearing_ls``
one landmark centre + laser range         present                 ``range_bearing``
one landmark centre + altitude            present                 ``altitude_bearing``
one landmark centre + its box's size      present                 ``size_bearing``
========================================  =====================  ==================

With the attitude, whenever the landmarks fix the pose without it, the attitude is checked
against theirs and dropped for the fix when they disagree (``PoseFix.attitude_prior``).

Every initial estimate is refined by the same MAP Gauss-Newton (:mod:`tracker.pose.refine`)
that also yields the 6x6 covariance.  Without attitude, PnP RANSAC runs first and names a
landmark that does not fit; with it, the all-landmarks-right hypothesis is tried first and a
RANSAC over landmark pairs names one.  The named landmark is dropped and the rest solved again
(without attitude from RANSAC's pose, when every point left fits it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from tracker.camera import CameraModel
from tracker.geometry import FloatArray, rotation_from_rpy
from tracker.pose.association import associate
from tracker.pose.config import PoseConfig
from tracker.pose.inputs import (
    CLAIM_CONFLICT,
    Context,
    Group,
    camera_arrays,
    firm_points,
    laser_for,
    laser_hits,
    make_groups,
    make_priors,
    point_set,
    range_prior,
    size_if_needed,
)
from tracker.pose.landmarks import (
    face_corners,
    face_rotation,
    landmark_normal_ned,
)
from tracker.pose.refine import (
    PointSet,
    Priors,
    Refined,
    arc_correction,
    initial_cost,
    point_errors_px,
    refine_pose,
    wrap_angle,
)
from tracker.pose.solvers import (
    bearing_consensus,
    bearing_least_squares,
    bearings_ned,
    ippe_candidates,
    pnp_all_points,
    pnp_ransac,
)
from tracker.pose.types import (
    AltitudeSample,
    AttitudeSample,
    MapLandmark,
    NoFix,
    Observation,
    PoseFix,
    PosePrior,
    RangeSample,
)
from tracker.pose.validate import check_observation, fresh_samples

#: Chi-square difference below which both planar (IPPE) solutions explain the corners.
_FLIP_CHI2 = 4.0
#: A landmark is dropped as an outlier only when this many are in play (3 stay to outvote it).
_MIN_TO_DROP = 4
#: A second IPPE solution starting this much (chi-square) worse is not refined.
_SKIP_CHI2 = 25.0
#: Why the pair consensus (attitude known) drops a landmark.
_CONSENSUS = "disagrees with the other landmarks' consensus"


@dataclass(frozen=True)
class _Solved:
    solver: str
    refined: Refined
    points: PointSet
    all_fit: bool = False  # already checked by _worst_group


@dataclass(frozen=True)
class _Failure:
    reason: str
    bad_group: int = -1
    #: a pose every other landmark's points fit (RANSAC's): the start once ``bad_group`` is gone
    hint: FloatArray | None = None


def solve_pose(
    observations: Sequence[Observation],
    landmarks: Sequence[MapLandmark],
    camera: CameraModel,
    time_us: int,
    *,
    attitude: AttitudeSample | None = None,
    altitude: AltitudeSample | None = None,
    laser: RangeSample | None = None,
    prior: PosePrior | None = None,
    config: PoseConfig | None = None,
    reset_counter: int = 0,
) -> PoseFix | NoFix:
    """Vehicle pose fix from landmark observations, or :class:`NoFix` with the reason.

    ``time_us`` is the frame's capture time; side samples further than
    ``config.max_sample_age_s`` from it are ignored (and said so in ``notes``).
    """
    cfg = config or PoseConfig()
    for i, obs in enumerate(observations):
        problem = check_observation(obs, camera.width, camera.height)
        if problem:
            return NoFix(time_us, f"observation {i}: {problem}")
    notes: list[str] = []
    attitude, altitude, laser = fresh_samples(time_us, attitude, altitude, laser, cfg, notes)
    assoc = associate(observations, landmarks, camera, prior, cfg)
    notes += list(assoc.notes)
    notes += [f"observation {a.observation_index} ambiguous: {a.reason}" for a in assoc.ambiguities]
    k, dist, r_body_cam = camera_arrays(camera)
    ctx = Context(camera, k, dist, r_body_cam, cfg, attitude, altitude, laser, dist.size > 0)
    by_id = {lm.landmark_id: lm for lm in landmarks}
    groups = make_groups(
        ctx,
        observations,
        [(m.observation_index, by_id[m.landmark_id]) for m in assoc.matches],
        notes,
    )
    if not groups:
        return NoFix(time_us, "no identified landmark in view", tuple(notes))
    if len(groups) == 1 and any(n.endswith(CLAIM_CONFLICT) for n in notes):
        # a misnamed detection was seen in this frame: the one landmark left may be the
        # misnamed one, and alone it cannot be cross-checked
        return NoFix(time_us, "after a landmark claimed twice only one is left: not trusted",
                     tuple(notes))
    before = list(notes)
    fix = _solve_robust(ctx, groups, time_us, reset_counter, notes)
    if attitude is None:
        return fix
    if not cfg.check_attitude:
        return replace(fix, attitude_prior="used") if isinstance(fix, PoseFix) else fix
    return _check_attitude(ctx, groups, fix, time_us, reset_counter, before)


def _check_attitude(
    ctx: Context,
    groups: list[Group],
    fix: PoseFix | NoFix,
    time_us: int,
    reset_counter: int,
    notes: list[str],
) -> PoseFix | NoFix:
    """``fix`` (solved with the autopilot's attitude; ``notes``: those before it was solved)
    unless the landmarks alone disagree
    with that attitude: then their own fix, saying that the prior was rejected.

    Whenever the view fixes the pose without the attitude (corners of one plate, four or
    more points of two or more landmarks) and every landmark agrees with that pose, the
    two solutions are compared as hypotheses: the attitude prior is consistent when adding
    it raises the cost by no more than ``attitude_gate_chi2`` (``chi2_with - chi2_alone``
    is chi-square with 3 DOF when it is; a likelihood-ratio test over the whole cost, not
    only its linearisation, so that a flat valley -- a far, head-on wall -- does not call a
    prior wrong that the pixels hardly mind).  When it is not, or when with the prior a
    landmark no longer fits, the prior is dropped for this fix: the autopilot's attitude is
    itself estimated from our fixes, and a fix that follows it would feed its error back.
    """
    if isinstance(fix, PoseFix) and _consistent_near(ctx, groups, fix):
        return replace(fix, attitude_prior="used")
    alone = _solve_robust(replace(ctx, attitude=None), groups, time_us, reset_counter, notes)
    if not isinstance(alone, PoseFix) or len(alone.landmark_ids) < len(groups):
        # not observable without the attitude: cannot check; or the landmarks disagree among
        # themselves and the subset they chose alone may be the wrong one: the attitude
        # (and its consensus) decides, as it must when one is misnamed
        return replace(fix, attitude_prior="used") if isinstance(fix, PoseFix) else fix
    if isinstance(fix, PoseFix) and set(fix.landmark_ids) == set(alone.landmark_ids):
        rise = fix.chi2 - alone.chi2
        if rise <= ctx.config.attitude_gate_chi2:
            return replace(fix, attitude_prior="used")
        why = f"adding it raises the chi-square by {rise:.1f} > {ctx.config.attitude_gate_chi2:g}"
    else:
        why = "with it the landmarks do not fit" if isinstance(fix, NoFix) else \
            "with it a landmark is dropped that fits without it"
    assert ctx.attitude is not None
    a = ctx.attitude
    d = wrap_angle(np.asarray(alone.attitude_rpy_rad) - (a.roll_rad, a.pitch_rad, a.yaw_rad))
    off = ", ".join(f"{math.degrees(v):+.1f}" for v in d)
    note = f"attitude prior rejected: the landmarks' roll, pitch, yaw differ by ({off}) deg; {why}"
    return replace(alone, notes=(*alone.notes, note), attitude_prior="rejected")


def _consistent_near(ctx: Context, groups: list[Group], fix: PoseFix) -> bool:
    """The cheap first test (no search): every landmark kept with the prior, and freed of
    it, refined from the fix, their cost falls by no more than the gate.  A refinement
    that fails (e.g. unobservable without the attitude) decides nothing: the full check
    solves without the attitude from scratch."""
    if len(fix.landmark_ids) < len(groups):
        return False
    free = replace(ctx, attitude=None)
    x0 = np.concatenate([fix.position_ned_m, fix.attitude_rpy_rad])
    ref = _refine(free, point_set(groups), make_priors(free, laser_for(free, groups, x0)), x0)
    return not ref.reason and fix.chi2 - ref.cost <= ctx.config.attitude_gate_chi2


def _solve_robust(
    ctx: Context, groups: list[Group], time_us: int, reset_counter: int, notes: list[str]
) -> PoseFix | NoFix:
    """Solve; while a landmark does not fit, drop it and solve again.

    A landmark is dropped only while at least three others remain to outvote it: two
    landmarks always agree with each other, so a pair left after a drop proves nothing.
    """
    active = list(groups)
    dropped = 0
    hint: FloatArray | None = None
    while True:
        out = _solve_once(ctx, active, hint)
        hint = None
        if isinstance(out, _Failure):
            if out.bad_group < 0 or len(active) == 1:
                return NoFix(time_us, out.reason, tuple(notes))
            bad, why, hint = out.bad_group, out.reason, out.hint
        else:
            bad, why = (-1, "") if out.all_fit else _worst_group(ctx, active, out.refined)
            if bad < 0:
                return _make_fix(ctx, active, out, time_us, reset_counter, dropped, notes)
        if len(active) < _MIN_TO_DROP:  # too few left to outvote a wrong one
            ids = ", ".join(repr(g.landmark.landmark_id) for g in active)
            why = why if len(active) == 1 else f"landmarks {ids} disagree ({why})"
            # of three, the two that fit name the third; of two, either may be the wrong one
            named = active[bad].landmark.landmark_id if len(active) >= 3 else None
            return NoFix(time_us, why, tuple(notes), outlier=named)
        notes.append(f"dropped {why}")
        del active[bad]
        dropped += 1


def _worst_group(ctx: Context, groups: list[Group], ref: Refined) -> tuple[int, str]:
    """Index of the landmark to drop with the reason, or (-1, "") when all fit."""
    normals = np.array([landmark_normal_ned(g.landmark) for g in groups])
    centres = np.array([g.landmark.position_ned_m for g in groups])
    front = np.einsum("ij,ij->i", normals, ref.position_ned_m - centres)
    if np.any(front <= 0.0):
        gi = int(np.argmin(front))
        return gi, f"landmark {groups[gi].landmark.landmark_id!r}: the camera is behind its face"
    counts = np.array([g.points_ned.shape[0] for g in groups])
    idx = np.repeat(np.arange(len(groups)), counts)
    per_point = np.bincount(idx, weights=ref.point_errors, minlength=len(groups)) / counts
    worst_i = int(np.argmax(per_point))
    worst = float(per_point[worst_i])
    if worst > ctx.config.outlier_chi2_per_point:
        lid = groups[worst_i].landmark.landmark_id
        return worst_i, f"landmark {lid!r}: reprojection error {math.sqrt(worst):.1f} sigma"
    return -1, ""


def _refine(ctx: Context, pts: PointSet, priors: Priors, x0: FloatArray) -> Refined:
    cfg = ctx.config
    return refine_pose(
        ctx.k, ctx.r_body_cam, pts, priors, x0, cfg.max_iterations, cfg.max_condition
    )


def _as_outcome(
    solver: str, ref: Refined, pts: PointSet, groups: list[Group]
) -> _Solved | _Failure:
    """Map a failed refinement (e.g. a point behind the camera) to the landmark to drop."""
    if not ref.reason:
        return _Solved(solver, ref, pts)
    if ref.bad_point < 0:
        return _Failure(ref.reason)
    bad = int(pts.landmark_index[ref.bad_point])
    lid = groups[bad].landmark.landmark_id
    return _Failure(f"landmark {lid!r}: {ref.reason}", bad)


def _solve_once(
    ctx: Context, groups: list[Group], hint: FloatArray | None = None
) -> _Solved | _Failure:
    """One solve over ``groups`` with the solver their geometry and priors call for.

    ``hint``: a pose the landmarks were found to agree on before one was dropped.
    """
    pts = point_set(groups)
    spread = float(np.max(np.ptp(pts.pixels, axis=0)))
    if pts.pixels.shape[0] > 1 and spread < ctx.config.min_point_spread_px:
        return _Failure(f"degenerate geometry: all image points within {spread:.1f} px")
    if len(groups) == 1 and groups[0].observation.all_corners:
        return _solve_ippe(ctx, groups[0], pts)
    if ctx.attitude is not None:
        return _solve_with_attitude(ctx, groups, pts)
    return _solve_without_attitude(ctx, groups, pts, hint)


def _solve_with_attitude(ctx: Context, groups: list[Group], pts: PointSet) -> _Solved | _Failure:
    """Bearing least squares (known rotation), then MAP refinement with the priors."""
    assert ctx.attitude is not None
    rpy = np.array([ctx.attitude.roll_rad, ctx.attitude.pitch_rad, ctx.attitude.yaw_rad])
    r_nb = rotation_from_rpy(*rpy)
    single = len(groups) == 1
    rng = range_prior(ctx, groups[0].landmark) if single else None
    b = bearings_ned(pts.pixels, ctx.k, r_nb @ ctx.r_body_cam)
    size = size_if_needed(ctx, groups[0], b[0], rng) if single else None
    alt = None if ctx.altitude is None else ctx.altitude.down_m
    firm = firm_points(groups)  # an extrapolated corner's bearing is neither start nor check
    p0 = bearing_least_squares(pts.points_ned[firm], b[firm], r_nb, alt, rng)
    if size is not None:
        p0 = size.point_ned - size.distance_m * b[0]
    if p0 is None:
        return _Failure(
            "one landmark centre: its distance is unobservable without corners, "
            "a laser range, the altitude or its size"
            if single
            else "degenerate geometry: bearings do not fix the position"
        )
    rel = pts.points_ned[firm] - p0
    ahead = np.einsum("ij,ij->i", rel, b[firm])
    cos = ahead / np.maximum(np.linalg.norm(rel, axis=1), 1e-12)
    worst_angle = float(np.max(np.arccos(np.clip(cos, -1.0, 1.0))))
    if not single and worst_angle > _consensus_threshold(ctx):  # cheap all-inlier test
        suspect = _consensus_outlier(ctx, pts, b)
        if suspect >= 0:
            return _outlier(groups, suspect, _CONSENSUS)
    if np.any(ahead <= 0):
        gi = int(pts.landmark_index[firm][int(np.argmin(ahead))])
        lid = groups[gi].landmark.landmark_id
        return _Failure(f"landmark {lid!r} would be behind the camera", gi)
    x0 = np.concatenate([p0, rpy])
    if single and rng is not None and not laser_hits(rng, groups[0].landmark, x0):
        rng = None
        size = size_if_needed(ctx, groups[0], b[0], None)
        if ctx.altitude is None and size is None:
            return _Failure(f"the laser beam misses landmark {groups[0].landmark.landmark_id!r}")
        if size is not None:
            x0[:3] = size.point_ned - size.distance_m * b[0]
    if not single:
        rng = laser_for(ctx, groups, x0)
    solver = "bearing_ls" if not single else (  # one plate's measured corners: bearing_ls
        "range_bearing" if rng else "altitude_bearing" if ctx.altitude
        else "size_bearing" if size else "bearing_ls")
    out = _as_outcome(solver, _refine(ctx, pts, make_priors(ctx, rng, size), x0), pts, groups)
    if single:
        return out
    if isinstance(out, _Solved) and _worst_group(ctx, groups, out.refined)[0] < 0:
        return replace(out, all_fit=True)
    suspect = _consensus_outlier(ctx, pts, b)  # the all-inlier hypothesis failed
    return _outlier(groups, suspect, _CONSENSUS) if suspect >= 0 else out


def _consensus_threshold(ctx: Context) -> float:
    """Angular inlier gate: the RANSAC pixel gate plus 3 sigma of the attitude prior."""
    assert ctx.attitude is not None
    a = ctx.attitude
    sigma = max(a.roll_pitch_sigma_rad, a.yaw_sigma_rad)
    return ctx.config.ransac_threshold_px / float(ctx.k[0, 0]) + 3.0 * sigma


def _consensus_outlier(ctx: Context, pts: PointSet, b: FloatArray) -> int:
    """The landmark the best pair of landmarks disagrees with most, or -1 (attitude known)."""
    thr = _consensus_threshold(ctx)
    per_group = bearing_consensus(pts.points_ned, b, pts.landmark_index, thr)
    if per_group is None:
        return -1
    worst = int(np.argmax(per_group))
    return worst if per_group[worst] >= thr else -1


def _outlier(
    groups: list[Group], gi: int, why: str, hint: FloatArray | None = None
) -> _Failure:
    """Drop landmark ``gi`` for ``why`` (``hint``: a pose every other landmark fits)."""
    return _Failure(f"landmark {groups[gi].landmark.landmark_id!r}: {why}", gi, hint)


def _solve_without_attitude(
    ctx: Context, groups: list[Group], pts: PointSet, hint: FloatArray | None
) -> _Solved | _Failure:
    """PnP in RANSAC over every point, refined; a landmark RANSAC rejects is named to drop.

    ``hint``: RANSAC's pose before a drop, which every point left fits (checked there).
    """
    n = pts.points_ned.shape[0]
    if len(groups) == 1:
        return _Failure("one landmark without its four corners and no attitude: "
                        "pose unobservable")
    if n < 4:
        return _Failure(f"{n} points and no attitude: need four or more (P3P is ambiguous)")
    centred = pts.points_ned - pts.points_ned.mean(axis=0)
    lam = np.linalg.eigvalsh(centred.T @ centred)  # squared singular values, ascending
    if lam[1] < 1e-6 * lam[2]:
        return _Failure("degenerate geometry: the landmark points are collinear")
    cfg = ctx.config
    thr = cfg.ransac_threshold_px
    if hint is not None:
        return _refine_pnp(ctx, groups, pts, "pnp_ransac", hint)
    dist_px = np.vstack([g.pixels_distorted for g in groups])
    res = pnp_ransac(pts.points_ned, dist_px, ctx.k, ctx.dist, ctx.r_body_cam, thr,
                     cfg.ransac_iterations, cfg.ransac_confidence)
    named = agreeing = -1
    if res is not None:
        cand, inlier = res
        # OpenCV's mask is its best minimal sample's; its pose is refitted on those inliers
        fit = point_errors_px(ctx.k, ctx.r_body_cam, pts, cand.x0) <= thr
        if np.all(fit):
            return _refine_pnp(ctx, groups, pts, "pnp", cand.x0)
        outliers = np.bincount(pts.landmark_index[~inlier], minlength=len(groups))
        named = int(np.argmax(outliers)) if outliers.max() > 0 else -1
        agreeing = int(np.sum(outliers == 0))  # one landmark's own corners always agree
        if named >= 0 and agreeing >= 3 and np.all(fit[pts.landmark_index != named]):
            return _outlier(groups, named, "RANSAC outlier", cand.x0)  # clear-cut
    # not clear-cut: no pose, too few landmarks agree, or the EPnP refit fits neither every
    # point nor all but the named landmark's (it is poor on (nearly) coplanar points, e.g. a
    # wall head-on): SQPnP through every point decides
    direct = pnp_all_points(pts.points_ned, dist_px, ctx.k, ctx.dist, ctx.r_body_cam)
    if direct is not None and (
        (res is not None and named < 0)  # RANSAC: every point an inlier
        or bool(np.all(point_errors_px(ctx.k, ctx.r_body_cam, pts, direct.x0) <= thr))
    ):
        return _refine_pnp(ctx, groups, pts, "pnp", direct.x0)
    if res is None:
        return _Failure("PnP RANSAC found no consistent pose")
    if named < 0:
        return _Failure("PnP found no pose through every point")
    if agreeing < 3:
        return _Failure("PnP RANSAC: no three landmarks agree on a pose")
    return _outlier(groups, named, "RANSAC outlier")


def _refine_pnp(
    ctx: Context, groups: list[Group], pts: PointSet, solver: str, x0: FloatArray
) -> _Solved | _Failure:
    priors = make_priors(ctx, laser_for(ctx, groups, x0))
    return _as_outcome(solver, _refine(ctx, pts, priors, x0), pts, groups)


def _solve_ippe(ctx: Context, g: Group, pts: PointSet) -> _Solved | _Failure:
    """Both IPPE solutions refined with the priors; refuse an unresolved planar flip."""
    lm = g.landmark
    square = abs(lm.width_m - lm.height_m) <= 1e-9 * max(lm.width_m, lm.height_m)
    cands = ippe_candidates(
        face_corners(lm.width_m, lm.height_m),
        g.pixels_distorted,
        ctx.k,
        ctx.dist,
        face_rotation(lm.facing_deg),
        np.asarray(lm.position_ned_m, dtype=np.float64),
        ctx.r_body_cam,
        square,
    )
    refined: list[Refined] = []
    for c in cands:
        priors = make_priors(ctx, laser_for(ctx, [g], c.x0))
        best = min((r.cost for r in refined if not r.reason), default=None)
        if best is not None and initial_cost(ctx.k, ctx.r_body_cam, pts, priors, c.x0) > (
            best + _SKIP_CHI2
        ):
            continue  # far worse from the start: not a rival local minimum worth refining
        refined.append(_refine(ctx, pts, priors, c.x0))
    ok = sorted((r for r in refined if not r.reason), key=lambda r: r.cost)
    solver = "ippe_square" if square else "ippe"
    if not ok:
        return _Failure(refined[0].reason if refined else "IPPE found no pose")
    if len(ok) > 1 and ok[1].cost - ok[0].cost < _FLIP_CHI2:
        gap = ok[1].position_ned_m - ok[0].position_ned_m
        m2 = float(gap @ np.linalg.solve(ok[0].covariance[:3, :3], gap))
        if m2 > 9.0:
            return _Failure(
                f"planar ambiguity: both IPPE solutions fit landmark {lm.landmark_id!r} "
                "(no attitude or range to tell them apart)"
            )
    return _Solved(solver, ok[0], pts)


def _make_fix(
    ctx: Context,
    groups: list[Group],
    out: _Solved,
    time_us: int,
    reset_counter: int,
    dropped: int,
    notes: list[str],
) -> PoseFix | NoFix:
    """The fix with quality ``100 * inlier ratio * 2^(-sigma_max / sigma_ref)``."""
    ref = out.refined
    cov = arc_correction(ref.covariance, ref.position_ned_m, out.points.points_ned)
    values = np.concatenate([ref.position_ned_m, ref.attitude_rpy_rad, cov.ravel()])
    if not np.all(np.isfinite(values)):
        return NoFix(time_us, "the solution is not finite", tuple(notes))
    sigma_max = float(np.sqrt(np.max(np.diag(cov)[:3])))
    if sigma_max > ctx.config.max_position_sigma_m:
        return NoFix(time_us, f"position 1-sigma {sigma_max:.1f} m is too large", tuple(notes))
    inlier_ratio = len(groups) / (len(groups) + dropped)
    quality = 100.0 * inlier_ratio * 2.0 ** (-sigma_max / ctx.config.quality_sigma_ref_m)
    pts = out.points
    if pts.scale_beta is None:
        rms = math.sqrt(float(np.mean(ref.point_errors * pts.sigma_px**2)) / 2.0)
    else:  # the whitened errors mix a plate's points: take them in pixels
        x = np.concatenate([ref.position_ned_m, ref.attitude_rpy_rad])
        rms = math.sqrt(float(np.mean(point_errors_px(ctx.k, ctx.r_body_cam, pts, x) ** 2)) / 2.0)
    p, a = ref.position_ned_m, ref.attitude_rpy_rad
    return PoseFix(
        time_us=time_us,
        position_ned_m=(float(p[0]), float(p[1]), float(p[2])),
        attitude_rpy_rad=(float(a[0]), float(a[1]), float(a[2])),
        covariance=cov,
        quality=max(1, min(100, round(quality))),
        landmark_ids=tuple(g.landmark.landmark_id for g in groups),
        solver=out.solver,
        reset_counter=reset_counter,
        reprojection_rms_px=rms,
        notes=tuple(notes),
        chi2=ref.cost,
        echo_covariance=ref.echo_covariance,
    )
