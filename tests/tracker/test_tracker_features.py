"""The feature bank (paper eq. 5) and feature images."""

from __future__ import annotations

import itertools

import numpy as np

from tracker.features import (
    GRAY_FEATURES,
    GRAY_LBP,
    GRAY_ORIENTATION,
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
    assert len(names) == 49 + len(GRAY_FEATURES)
    assert {"gray:gradient", "gray:orientation", "gray:lbp"} <= names


def test_orientation_tells_edge_directions_apart_and_flat_pixels_from_edges() -> None:
    """A dark-to-bright step and its mirror land in opposite sectors; flat pixels in bin 0."""
    step = np.full((9, 12, 3), 50, np.uint8)
    step[:, 6:] = 200
    rising = feature_bins(step, (GRAY_ORIENTATION,), 16)[0]
    falling = feature_bins(step[:, ::-1].copy(), (GRAY_ORIENTATION,), 16)[0]
    assert rising[4, 0] == 0 and rising[4, 11] == 0  # flat
    assert rising[4, 6] == 2  # gradient along +x: first sector
    assert falling[4, 5] == 2 + 7  # along -x: half a turn later (14 sectors)


def test_lbp_codes_flat_spot_and_texture() -> None:
    """Flat: no brighter neighbour (code 0); a dark dot: 8 (uniform); a checkerboard: 9."""
    flat = np.full((5, 5, 3), 120, np.uint8)
    dot = flat.copy()
    dot[2, 2] = 20
    checker = np.where((np.indices((5, 5)).sum(axis=0) % 2)[:, :, None] == 0, 200, 20)
    bins = [feature_bins(p.astype(np.uint8), (GRAY_LBP,), 10)[0, 2, 2] for p in (flat, dot)]
    assert bins == [0, 8]
    alternating = feature_bins(np.repeat(checker, 3, axis=2).astype(np.uint8), (GRAY_LBP,), 10)
    assert alternating[0, 2, 1] == 9  # dark centre: bright, dark, bright ... around it


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
    assert planes.shape == (len(GRAY_FEATURES), 8, 8)
    assert planes[0, 0, 0] < planes[0, 7, 7]  # intensity rises with the grey level
