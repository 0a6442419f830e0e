"""The analytic Jacobian of the refinement matches finite differences (pixels and priors)."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from tracker.camera import CameraModel
from tracker.geometry import rotation_from_rpy
from tracker.pose.refine import (
    PointSet,
    Priors,
    RangePrior,
    _residuals,
    point_errors_px,
    wrap_angle,
)


def _problem() -> tuple[np.ndarray, np.ndarray, PointSet, Priors, np.ndarray]:
    cam = CameraModel(mount_rpy_deg=(3.0, -20.0, 5.0))
    rng = np.random.default_rng(4)
    pts = rng.uniform([10, -5, -6], [25, 5, 0], size=(7, 3))
    x = np.array([1.0, -2.0, -4.0, 0.1, -0.2, 0.7])
    pixels = rng.uniform(0, 480, size=(7, 2))
    rp = RangePrior(
        12.0, 0.05, np.array([0.6, 0.0, 0.8]), np.array([0.0, 0.0, 2.0]), np.array([0, 0, -1.0])
    )
    priors = Priors(np.array([0.12, -0.18, 0.65]), np.array([0.01, 0.02, 0.03]), -4.2, 0.2, rp)
    ps = PointSet(pts, pixels, rng.uniform(0.5, 2, 7), np.arange(7, dtype=np.int64))
    return cam.matrix, cam.r_body_cam, ps, priors, x


def test_jacobian_matches_central_differences() -> None:
    k, r_bc, ps, priors, x = _problem()
    _, jac, _ = _residuals(x, k, r_bc, ps, priors)
    num = np.zeros_like(jac)
    h = 1e-6
    for i in range(6):
        dx = np.zeros(6)
        dx[i] = h
        rp, _, _ = _residuals(x + dx, k, r_bc, ps, priors)
        rm, _, _ = _residuals(x - dx, k, r_bc, ps, priors)
        num[:, i] = (rp - rm) / (2 * h)
    np.testing.assert_allclose(jac, num, rtol=1e-5, atol=1e-5 * np.abs(num).max())


def test_residual_rotation_is_the_shared_zyx_convention() -> None:
    k, r_bc, ps, _, x = _problem()
    res, _, z = _residuals(x, k, r_bc, ps, Priors())
    xc = (ps.points_ned - x[:3]) @ (rotation_from_rpy(*x[3:]) @ r_bc)
    np.testing.assert_allclose(z, xc[:, 2])
    u = k[0, 0] * xc[:, 0] / xc[:, 2] + k[0, 2]
    np.testing.assert_allclose(res[0::2], (u - ps.pixels[:, 0]) / ps.sigma_px)


def test_point_errors_are_opencv_reprojection_distances() -> None:
    k, r_bc, ps, _, x = _problem()
    r_cam_ned = (rotation_from_rpy(*x[3:]) @ r_bc).T
    rvec, _ = cv2.Rodrigues(r_cam_ned)
    tvec = -r_cam_ned @ x[:3]
    proj, _ = cv2.projectPoints(ps.points_ned, rvec, tvec, k, None)
    expected = np.linalg.norm(proj.reshape(-1, 2) - ps.pixels, axis=1)
    np.testing.assert_allclose(point_errors_px(k, r_bc, ps, x), expected, rtol=1e-9)


def test_a_point_behind_the_camera_has_an_infinite_error() -> None:
    k, r_bc, ps, _, x = _problem()
    r_ned_cam = rotation_from_rpy(*x[3:]) @ r_bc
    behind = x[:3] - 10.0 * r_ned_cam[:, 2]  # 10 m straight behind the optical axis
    pts = replace(ps, points_ned=np.vstack([ps.points_ned[:-1], behind]))
    err = point_errors_px(k, r_bc, pts, x)
    assert np.isinf(err[-1]) and np.all(np.isfinite(err[:-1]))


def test_wrap_angle() -> None:
    np.testing.assert_allclose(
        wrap_angle(np.array([3 * np.pi, -3.5 * np.pi, 0.1])), [-np.pi, 0.5 * np.pi, 0.1]
    )


def _with_scale_error(ps: PointSet, groups: np.ndarray, width_sigma: float) -> PointSet:
    """``ps`` with points grouped as landmarks whose outline may scale as a whole."""
    dirs, beta = np.zeros((len(groups), 2)), np.zeros(len(groups))
    for g in np.unique(groups):
        sel = groups == g
        u = ps.pixels[sel] - ps.pixels[sel].mean(axis=0)
        norm = np.linalg.norm(u)
        sigma = ps.sigma_px[sel][0]
        a_uu = (width_sigma / 40.0) ** 2 * norm**2  # a plate 40 px wide
        dirs[sel], beta[sel] = u / norm, 1.0 - sigma / np.sqrt(sigma**2 + a_uu)
    return PointSet(ps.points_ned, ps.pixels, ps.sigma_px, groups, dirs, beta)


def test_a_common_scale_error_is_whitened_like_its_full_covariance() -> None:
    """With a landmark's pixel errors ``sigma^2 I + (s/w)^2 u u^T``, the residuals and the
    Jacobian are whitened by that covariance's inverse square root: ``J^T J`` and ``r^T r``
    equal those of a dense whitening, and the Jacobian still matches finite differences."""
    k, r_bc, ps, priors, x = _problem()
    groups = np.array([0, 0, 0, 0, 1, 1, 1], dtype=np.int64)
    sigma = np.where(groups == 0, 0.7, 1.3)
    ps = PointSet(ps.points_ned, ps.pixels, sigma, groups)
    scaled = _with_scale_error(ps, groups, width_sigma=0.5)
    plain_r, plain_j, _ = _residuals(x, k, r_bc, ps, Priors())
    r, j, _ = _residuals(x, k, r_bc, scaled, Priors())
    # dense: undo the plain 1/sigma whitening, then whiten by Sigma^-1/2 per landmark
    raw_r, raw_j = plain_r * np.repeat(sigma, 2), plain_j * np.repeat(sigma, 2)[:, None]
    want_rr, want_jj = 0.0, np.zeros((6, 6))
    for g in (0, 1):
        rows = np.repeat(groups == g, 2)
        u = (ps.pixels[groups == g] - ps.pixels[groups == g].mean(axis=0)).ravel()
        cov = sigma[groups == g][0] ** 2 * np.eye(rows.sum()) + (0.5 / 40.0) ** 2 * np.outer(u, u)
        inv = np.linalg.inv(cov)
        want_rr += raw_r[rows] @ inv @ raw_r[rows]
        want_jj += raw_j[rows].T @ inv @ raw_j[rows]
    np.testing.assert_allclose(r @ r, want_rr, rtol=1e-10)
    np.testing.assert_allclose(j.T @ j, want_jj, rtol=1e-10)
    assert not np.allclose(j.T @ j, plain_j.T @ plain_j, rtol=1e-3)  # it does change things
    _, jac, _ = _residuals(x, k, r_bc, scaled, priors)
    num = np.zeros_like(jac)
    for i in range(6):
        dx = np.zeros(6)
        dx[i] = 1e-6
        num[:, i] = (_residuals(x + dx, k, r_bc, scaled, priors)[0]
                     - _residuals(x - dx, k, r_bc, scaled, priors)[0]) / 2e-6
    np.testing.assert_allclose(jac, num, rtol=1e-5, atol=1e-5 * np.abs(num).max())
