"""Kernel histograms and the Bhattacharyya likelihood (paper eq. 2-4)."""

from __future__ import annotations

import numpy as np

from tracker.appearance import (
    bhattacharyya,
    bhattacharyya_distance,
    epanechnikov_grid,
    joint_planes,
    kernel_histograms,
    particle_likelihood,
)


def test_epanechnikov_weights_fall_from_centre() -> None:
    offsets, w = epanechnikov_grid(16)
    r2 = (offsets**2).sum(axis=1)
    assert np.all(r2 < 1) and np.allclose(w, 1 - r2)
    assert w[np.argmin(r2)] > 0.99 and w.min() < 0.2


def test_histograms_sum_to_one_and_match_themselves() -> None:
    rng = np.random.default_rng(0)
    planes = rng.integers(0, 8, (2, 50, 50))
    centres = np.array([[25.0, 25.0], [10.0, 10.0]])
    halves = np.array([[8.0, 6.0], [8.0, 6.0]])
    h = kernel_histograms(planes, centres, halves, 16, 8)
    assert h.shape == (2, 2, 8)
    assert np.allclose(h.sum(axis=-1), 1.0)
    rho = bhattacharyya(h, h[0])
    assert np.isclose(rho[0], 1.0) and rho[1] < 1.0
    assert np.isclose(bhattacharyya_distance(rho)[0], 0.0)


def test_likelihood_is_exp_minus_omega_s_squared() -> None:
    rho = np.array([1.0, 0.9, 0.5])
    assert np.allclose(particle_likelihood(rho, 20.0), np.exp(-20.0 * (1 - rho)))


def test_joint_planes_index_combinations() -> None:
    planes = np.array([[[0, 15]], [[15, 0]]])
    joint = joint_planes(planes, 16, 4)
    assert joint.tolist() == [[[3, 12]]]
