"""The analytic Jacobian of the refinement matches finite differences (pixels and priors)."""

from __future__ import annotations

import numpy as np

from tracker.camera import CameraModel
from tracker.geometry import rotation_from_rpy
from tracker.pose.refine import PointSet, Priors, RangePrior, _residuals, wrap_angle


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


def test_wrap_angle() -> None:
    np.testing.assert_allclose(
        wrap_angle(np.array([3 * np.pi, -3.5 * np.pi, 0.1])), [-np.pi, 0.5 * np.pi, 0.1]
    )
