"""The feature bank (paper eq. 5) and feature images."""

from __future__ import annotations

import itertools

import numpy as np

from tracker.features import (
    GRAY_FEATURES,
    colour_feature_bins,
    colour_weights,
    feature_bins,
    feature_name,
    is_grayscale,
)


def test_feature_bank_has_49_distinct_features() -> None:
    """124 non-zero triples in {-2..2}^3, minus positive multiples and sign flips, leave 49."""
    w = colour_weights()
    assert w.shape == (49, 3)
    assert np.abs(w).max() <= 2
    assert not np.any(np.all(w == 0, axis=1))
    unit = w / np.linalg.norm(w, axis=1, keepdims=True)
    cos = np.abs(unit @ unit.T)
    np.fill_diagonal(cos, 0)
    assert cos.max() < 1 - 1e-9, "two features are multiples or negations of each other"
    # every one of the 124 triples is represented by one of the 49
    for t in itertools.product(range(-2, 3), repeat=3):
        if any(t):
            v = np.array(t) / np.linalg.norm(t)
            assert np.isclose(np.abs(unit @ v).max(), 1.0)


def test_feature_names_are_readable() -> None:
    names = {feature_name(i) for i in range(49)} | {feature_name(i) for i in GRAY_FEATURES}
    assert len(names) == 52
    assert "gray:gradient" in names


def test_bins_follow_the_feature_value() -> None:
    """R-G: a red pixel lands in a high bin, a green pixel in a low one, all within range."""
    rid = next(i for i, w in enumerate(colour_weights()) if tuple(w) == (1, -1, 0))
    patch = np.zeros((1, 3, 3), np.uint8)
    patch[0, 0] = (0, 0, 255)  # BGR red
    patch[0, 1] = (0, 255, 0)  # green
    patch[0, 2] = (0, 0, 0)
    bins = colour_feature_bins(patch, (rid,), 16)[0, 0]
    assert bins[0] == 15 and bins[1] == 0 and bins[2] in (7, 8)
    all_bins = colour_feature_bins(
        np.random.default_rng(0).integers(0, 256, (8, 8, 3), dtype=np.uint8), tuple(range(49)), 16
    )
    assert all_bins.min() >= 0 and all_bins.max() <= 15


def test_grayscale_is_detected_and_has_its_own_features() -> None:
    grey = np.repeat(np.arange(64, dtype=np.uint8).reshape(8, 8, 1), 3, axis=2)
    assert is_grayscale(grey, 1.0)
    colour = grey.copy()
    colour[:, :, 2] = 200
    assert not is_grayscale(colour, 1.0)
    planes = feature_bins(grey, GRAY_FEATURES, 16)
    assert planes.shape == (3, 8, 8)
    assert planes[0, 0, 0] < planes[0, 7, 7]  # intensity rises with the grey level
