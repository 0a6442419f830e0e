"""Maximum a posteriori pose refinement (Gauss-Newton) and its covariance.

State ``x = (p_n, p_e, p_d, roll, pitch, yaw)``: the vehicle (= camera centre) position in
NED and the body attitude (ZYX Euler).  Residuals, each whitened by its 1-sigma:

* pixels:   ``r_i = (pi(K, R_cam_ned (L_i - p)) - u_i) / sigma_i``   (ideal, undistorted px)
* attitude: ``r = wrap(rpy - rpy_0) / sigma``                         (autopilot prior)
* altitude: ``r = (p_d - d_0) / sigma``
* range:    ``r = (n.(c - p) / n.(R_nb a_b) - d) / sigma``           (beam meets the face plane)
* distance: ``r = (|L - p| - d) / sigma``                             (a box's size on screen)

Gauss-Newton ``dx = -(J^T J)^-1 J^T r``; at convergence the covariance is the inverse of the
whitened normal matrix ``P = (J^T J)^-1`` (first order, Cramer-Rao for Gaussian noise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt

from tracker.geometry import FloatArray

IntArray = npt.NDArray[np.int64]

_MIN_DEPTH_M = 1e-3


@dataclass(frozen=True)
class PointSet:
    """Correspondences: Nx3 NED points, Nx2 ideal pixels, N sigmas (px), N landmark indices.

    ``scale_dir`` / ``scale_beta`` (optional): a landmark's pixel errors may share parts
    common to its outline, ``Sigma = sigma^2 I + sum_m a_m u_m u_m^T`` over its 2k pixel
    coordinates, along orthonormal modes ``u_m`` (e.g. the quadrilateral's scale about its
    centre: the corners' offsets from it; or its perspective, docs/pose.md).  ``scale_dir``
    holds each point's two components of its landmark's unit modes (N x 2, or N x 2 x M for
    M modes), ``scale_beta`` each mode's ``beta_m = 1 - sigma / sqrt(sigma^2 + a_m)`` for
    each point (N or N x M; 0: none), so that ``(I - sum_m beta_m u_m u_m^T) / sigma``
    whitens them (:func:`_decorrelate`).
    """

    points_ned: FloatArray
    pixels: FloatArray
    sigma_px: FloatArray
    landmark_index: IntArray
    scale_dir: FloatArray | None = None
    scale_beta: FloatArray | None = None

    @cached_property
    def same_landmark(self) -> FloatArray:
        """N x N: 1 where two points belong to the same landmark (once per set: every
        residual evaluation of a refinement uses it, :func:`_decorrelate`)."""
        index = self.landmark_index
        return (index[:, None] == index[None, :]).astype(np.float64)


@dataclass(frozen=True)
class RangePrior:
    """A laser range along ``axis_body`` meeting the plane (``plane_point``, ``plane_normal``)."""

    distance_m: float
    sigma_m: float
    axis_body: FloatArray
    plane_point: FloatArray
    plane_normal: FloatArray


@dataclass(frozen=True)
class DistancePrior:
    """The distance from the camera to a landmark's centre, e.g. from its size on screen."""

    point_ned: FloatArray
    distance_m: float
    sigma_m: float


@dataclass(frozen=True)
class Priors:
    """Optional prior information from the autopilot, the rangefinder and a box's size."""

    attitude_rpy_rad: FloatArray | None = None
    attitude_sigma_rad: FloatArray | None = None
    altitude_down_m: float | None = None
    altitude_sigma_m: float = 0.1
    range: RangePrior | None = None
    distance: DistancePrior | None = None


@dataclass(frozen=True)
class Refined:
    """Result of :func:`refine_pose`; ``reason`` is set when it failed."""

    position_ned_m: FloatArray
    attitude_rpy_rad: FloatArray
    covariance: FloatArray
    point_errors: FloatArray  # N normalised squared pixel errors
    reason: str = ""
    bad_point: int = -1  # the point behind the camera, when that is the reason
    cost: float = 0.0  # whitened residual sum of squares (chi-square) at the solution
    #: the part of ``covariance`` that the autopilot's own attitude and height priors carry,
    #: ``P J_a^T J_a P`` over their rows (``P`` = the covariance): what an error of the
    #: autopilot's estimate moves the solution by (None: no such prior)
    echo_covariance: FloatArray | None = None


def _rotation_and_derivatives(rpy: FloatArray) -> FloatArray:
    """``R = Rz(y) Ry(p) Rx(r)``, ``dR/droll``, ``dR/dpitch`` and ``dR/dyaw`` stacked (4x3x3)."""
    sr, cr = math.sin(rpy[0]), math.cos(rpy[0])
    sp, cp = math.sin(rpy[1]), math.cos(rpy[1])
    sy, cy = math.sin(rpy[2]), math.cos(rpy[2])
    m = np.array(
        [
            [  # R
                [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                [-sp, cp * sr, cp * cr],
            ],
            [  # dR/droll
                [0.0, cy * sp * cr + sy * sr, -cy * sp * sr + sy * cr],
                [0.0, sy * sp * cr - cy * sr, -sy * sp * sr - cy * cr],
                [0.0, cp * cr, -cp * sr],
            ],
            [  # dR/dpitch
                [-cy * sp, cy * cp * sr, cy * cp * cr],
                [-sy * sp, sy * cp * sr, sy * cp * cr],
                [-cp, -sp * sr, -sp * cr],
            ],
            [  # dR/dyaw
                [-sy * cp, -sy * sp * sr - cy * cr, -sy * sp * cr + cy * sr],
                [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                [0.0, 0.0, 0.0],
            ],
        ]
    )
    return m


def wrap_angle(a: FloatArray) -> FloatArray:
    """Wrap angles to [-pi, pi)."""
    return np.asarray((a + np.pi) % (2.0 * np.pi) - np.pi, dtype=np.float64)


def _residuals(
    x: FloatArray, k: FloatArray, r_body_cam: FloatArray, pts: PointSet, priors: Priors
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Whitened residuals (u0, v0, u1, v1, ..., priors), Jacobian (rows x 6), point depths."""
    rot = _rotation_and_derivatives(x[3:])
    r_nb, dr_nb = rot[0], rot[1:]
    # one product gives X_c = R_cam_ned (L - p) and dX_c/dtheta_i = (dR_nb_i R_body_cam)^T (L - p)
    mats = rot @ r_body_cam  # 4 x 3 x 3
    rel = pts.points_ned - x[:3]
    prod = rel @ mats.transpose(1, 0, 2).reshape(3, 12)  # N x (4 x 3)
    xc = prod[:, :3]
    n = xc.shape[0]
    z = xc[:, 2]
    zs = np.where(np.abs(z) < _MIN_DEPTH_M, _MIN_DEPTH_M, z)
    xn = xc[:, :2] / zs[:, None]
    f = np.array([k[0, 0], k[1, 1]])
    w = 1.0 / pts.sigma_px
    res = ((f * xn + k[:2, 2] - pts.pixels) * w[:, None]).reshape(-1)  # u = fx X/Z + cx
    # dX_c/dx per component (N x 6): position columns -R_cam_ned, angle columns from prod
    d = np.empty((n, 3, 6))
    d[:, :, :3] = -mats[0].T
    d[:, :, 3:] = prod[:, 3:].reshape(n, 3, 3).transpose(0, 2, 1)
    # d(u, v) = f w / Z (dX - (X/Z) dZ) for X -> u and Y -> v
    jac = (d[:, :2, :] - xn[:, :, None] * d[:, 2:3, :]) * (f[None, :] * (w / zs)[:, None])[
        :, :, None
    ]
    jac = jac.reshape(2 * n, 6)
    if pts.scale_dir is not None and pts.scale_beta is not None:
        both = _decorrelate(np.column_stack([res, jac]), pts)
        res, jac = both[:, 0], both[:, 1:]
    rows_r, rows_j = [res], [jac]
    _prior_rows(x, r_nb, list(dr_nb), priors, rows_r, rows_j)
    if len(rows_r) == 1:
        return res, jac, z
    return np.concatenate(rows_r), np.vstack(rows_j), z


def _decorrelate(rows: FloatArray, pts: PointSet) -> FloatArray:
    """``(I - sum_m beta_m u_m u_m^T)`` applied, landmark by landmark, to (2N, C) whitened
    pixel rows."""
    assert pts.scale_dir is not None and pts.scale_beta is not None
    n = pts.points_ned.shape[0]
    r = rows.reshape(n, 2, -1)
    dirs = pts.scale_dir.reshape(n, 2, -1)  # N x 2 x M
    beta = pts.scale_beta.reshape(n, -1)  # N x M
    along = np.einsum("njm,njc->nmc", dirs, r)  # u_m^T r, point by point
    # beta u^T r summed over each landmark's points
    back = beta[:, :, None] * np.einsum("nk,kmc->nmc", pts.same_landmark, along)
    return np.asarray((r - np.einsum("njm,nmc->njc", dirs, back)).reshape(rows.shape))


def _prior_rows(
    x: FloatArray,
    r_nb: FloatArray,
    dr_nb: list[FloatArray],
    priors: Priors,
    rows_r: list[FloatArray],
    rows_j: list[FloatArray],
) -> None:
    """Append the whitened prior residuals and Jacobian rows."""
    if priors.attitude_rpy_rad is not None and priors.attitude_sigma_rad is not None:
        s = priors.attitude_sigma_rad
        rows_r.append(wrap_angle(x[3:] - priors.attitude_rpy_rad) / s)
        rows_j.append(np.eye(3, 6, 3) / s[:, None])  # d/d(rpy) = diag(1 / s)
    if priors.altitude_down_m is not None:
        rows_r.append(np.array([(x[2] - priors.altitude_down_m) / priors.altitude_sigma_m]))
        rows_j.append(np.array([[0.0, 0.0, 1.0 / priors.altitude_sigma_m, 0.0, 0.0, 0.0]]))
    dp = priors.distance
    if dp is not None:  # r = (|L - p| - d) / sigma
        rel = dp.point_ned - x[:3]
        dist = max(float(np.linalg.norm(rel)), _MIN_DEPTH_M)
        rows_r.append(np.array([(dist - dp.distance_m) / dp.sigma_m]))
        rows_j.append(np.concatenate([-rel / dist, np.zeros(3)])[None, :] / dp.sigma_m)
    rp = priors.range
    if rp is not None:
        n = rp.plane_normal
        a = r_nb @ rp.axis_body
        na = float(n @ a)
        if abs(na) < 1e-6:
            na = 1e-6
        t = float(n @ (rp.plane_point - x[:3])) / na  # t = n.(c - p) / n.a
        rows_r.append(np.array([(t - rp.distance_m) / rp.sigma_m]))
        jp = -n / na
        ja = np.array([-t * float(n @ (d @ rp.axis_body)) / na for d in dr_nb])
        rows_j.append(np.hstack([jp, ja])[None, :] / rp.sigma_m)


def initial_cost(
    k: FloatArray, r_body_cam: FloatArray, pts: PointSet, priors: Priors, x: FloatArray
) -> float:
    """Whitened residual sum of squares at ``x`` (no refinement)."""
    r, _, _ = _residuals(np.asarray(x, dtype=np.float64), k, r_body_cam, pts, priors)
    return float(r @ r)


def point_errors_px(
    k: FloatArray, r_body_cam: FloatArray, pts: PointSet, x: FloatArray
) -> FloatArray:
    """Reprojection error magnitude (px, ideal pixels) of every point at ``x``; infinite for
    a point less than :data:`_MIN_DEPTH_M` in front of the camera (it cannot be seen)."""
    x = np.asarray(x, dtype=np.float64)
    r_ned_cam = _rotation_and_derivatives(x[3:])[0] @ r_body_cam
    xc = (pts.points_ned - x[:3]) @ r_ned_cam  # rows: R_cam_ned (L - p)
    z = xc[:, 2]
    seen = z >= _MIN_DEPTH_M
    uv = xc[:, :2] / np.where(seen, z, 1.0)[:, None] * (k[0, 0], k[1, 1]) + k[:2, 2]
    return np.where(seen, np.hypot(*(uv - pts.pixels).T), np.inf)


def refine_pose(
    k: FloatArray,
    r_body_cam: FloatArray,
    pts: PointSet,
    priors: Priors,
    x0: FloatArray,
    max_iterations: int = 10,
    max_condition: float = 1e12,
) -> Refined:
    """Gauss-Newton from ``x0`` (6,) to the MAP pose, with its covariance ``(J^T J)^-1``."""
    x = np.asarray(x0, dtype=np.float64).copy()
    r, j, z = _residuals(x, k, r_body_cam, pts, priors)
    cost = float(r @ r)
    for _ in range(max_iterations):
        h = j.T @ j
        g = j.T @ r
        try:
            dx = -np.linalg.solve(h, g)
        except np.linalg.LinAlgError:
            return _failed(x, "degenerate geometry: singular normal matrix")
        # nearly converged when the step is well below the uncertainty (dx^T H dx = -g^T dx,
        # in sigma^2): take it without re-linearising; what is left is second order
        if float(-g @ dx) < 1e-2:
            x = x + dx
            break
        accepted = False
        for step in (1.0, 0.5, 0.25, 0.125):  # step halving keeps the cost decreasing
            xn = x + step * dx
            rn, jn, zn = _residuals(xn, k, r_body_cam, pts, priors)
            cn = float(rn @ rn)
            if cn <= cost * (1.0 + 1e-12):
                x, r, j, z, cost, accepted = xn, rn, jn, zn, cn, True
                break
        if not accepted:
            break
    return _finish(x, r, j, z, pts, max_condition, _autopilot_rows(priors))


def _autopilot_rows(priors: Priors) -> int:
    """How many prior rows (right after the pixels', :func:`_prior_rows`' order) are the
    autopilot's own estimate: its attitude (3) and its height (1)."""
    attitude = priors.attitude_rpy_rad is not None and priors.attitude_sigma_rad is not None
    return 3 * attitude + (priors.altitude_down_m is not None)


def _finish(
    x: FloatArray, r: FloatArray, j: FloatArray, z: FloatArray, pts: PointSet, max_cond: float,
    autopilot_rows: int = 0,
) -> Refined:
    """Covariance at the solution, cheirality and conditioning checks."""
    if np.any(z <= _MIN_DEPTH_M):
        bad = int(np.argmin(z))
        return _failed(x, f"point {bad} is behind the camera", index=bad)
    h = j.T @ j
    scale = np.sqrt(np.diag(h))
    if np.any(scale <= 0) or not np.all(np.isfinite(h)):
        return _failed(x, "degenerate geometry: a pose parameter is unobservable")
    outer = np.outer(scale, scale)
    lam, vec = np.linalg.eigh(h / outer)  # the scaled normal matrix, for its condition
    if lam[0] <= 0 or lam[-1] > max_cond * lam[0]:
        cond = lam[-1] / lam[0] if lam[0] > 0 else float("inf")
        return _failed(x, f"degenerate geometry: normal matrix condition {cond:.3g}")
    cov = (vec / lam) @ vec.T / outer  # P = H^-1
    cov = 0.5 * (cov + cov.T)
    n = pts.points_ned.shape[0]
    errs = np.sum(r[: 2 * n].reshape(n, 2) ** 2, axis=1)
    x[3:] = wrap_angle(x[3:])
    echo = None
    if autopilot_rows:
        ja = j[2 * n: 2 * n + autopilot_rows] @ cov
        echo = ja.T @ ja
    return Refined(x[:3].copy(), x[3:].copy(), cov, errs, cost=float(r @ r),
                   echo_covariance=echo)


def arc_correction(cov: FloatArray, position: FloatArray, points_ned: FloatArray) -> FloatArray:
    """Second-order term for the curved valley of bearing-dominated geometry (a new 6x6).

    Seen from afar, the landmarks fix the direction to them well but let the vehicle slide
    sideways while turning; the valley of the cost is curved, and the tangent (linear)
    picture misses a departure along the line of sight ``u`` of order ``d phi^2 / 2`` for an
    angular error ``phi ~ N(0, s^2)``, whose second moment is ``3 d^2 s^4 / 4`` (cf. the
    converted-measurement bias of Lerro & Bar-Shalom, 1993).  Its sign depends on the
    geometry (measured: away from a head-on wall), so it is added as a second moment, not
    corrected as a bias.  With ``s_i^2 = lambda_i / d^2`` for the two position variances
    ``lambda_i`` across ``u``: ``P_pos += 3/4 (lambda_1^2 + lambda_2^2) / d^2 u u^T``.
    """
    rel = points_ned.mean(axis=0) - position
    d = float(np.linalg.norm(rel))
    if d <= 0:
        return cov
    u = rel / d
    uu = np.outer(u, u)
    proj = np.eye(3) - uu
    across = proj @ cov[:3, :3] @ proj  # eigenvalues lambda_1, lambda_2 and 0 (along u)
    out = cov.copy()
    out[:3, :3] += 0.75 * float(np.sum(across * across)) / d**2 * uu  # sum lambda^2 = |.|_F^2
    return out


def _failed(x: FloatArray, reason: str, index: int = -1) -> Refined:
    """A failed refinement carrying the reason (and the offending point index, if any)."""
    nan6 = np.full((6, 6), np.nan)
    return Refined(x[:3].copy(), x[3:].copy(), nan6, np.zeros(0), reason, index)
