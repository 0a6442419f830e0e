"""Particle-filter building blocks."""

from __future__ import annotations

import numpy as np

from tracker.particles import (
    integral_images,
    mean_shift,
    motion_noise,
    propagate,
    systematic_resample,
    weighted_estimate,
)


def test_motion_noise_is_mean_displacement_over_last_n() -> None:
    centres = [(0.0, 0.0), (100.0, 0.0), (103.0, 4.0), (106.0, 8.0)]
    assert np.isclose(motion_noise(centres, 2, 1.0, 0.0, 100.0), 5.0)
    assert np.isclose(motion_noise(centres, 2, 2.0, 0.0, 8.0), 8.0)  # clipped to high
    assert np.isclose(motion_noise(centres[:1], 2, 1.0, 0.0, 7.0), 7.0)  # no history


def test_systematic_resampling_follows_weights_and_seed() -> None:
    w = np.array([0.0, 0.7, 0.3, 0.0])
    idx = systematic_resample(w, np.random.default_rng(1))
    assert set(idx.tolist()) <= {1, 2}
    assert np.bincount(idx, minlength=4)[1] in (2, 3)
    again = systematic_resample(w, np.random.default_rng(1))
    assert idx.tolist() == again.tolist()


def test_propagate_uses_the_generator_only() -> None:
    p = np.tile([10.0, 20.0, 1.0], (50, 1))
    a = propagate(p, 3.0, 0.05, (0.5, 2.0), np.random.default_rng(7))
    b = propagate(p, 3.0, 0.05, (0.5, 2.0), np.random.default_rng(7))
    assert np.array_equal(a, b)
    assert 2.0 < a[:, 0].std() < 4.0
    assert a[:, 2].min() >= 0.5


def test_mean_shift_climbs_to_the_blob() -> None:
    img = np.zeros((100, 100), np.float32)
    img[60:70, 30:40] = 1.0
    start = np.array([[30.0, 58.0], [40.0, 70.0]])
    end = mean_shift(integral_images(img), start, np.array([[10.0, 10.0]] * 2), 10)
    assert np.allclose(end, [[35.0, 65.0], [35.0, 65.0]], atol=0.6)


def test_weighted_estimate() -> None:
    p = np.array([[0.0, 0.0, 1.0], [10.0, 10.0, 2.0]])
    assert np.allclose(weighted_estimate(p, np.array([1.0, 3.0])), [7.5, 7.5, 1.75])
