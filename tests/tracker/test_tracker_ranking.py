"""Variance-ratio ranking (paper eq. 6-8)."""

from __future__ import annotations

import numpy as np

from tracker.features import colour_weights, feature_bins
from tracker.ranking import (
    log_likelihood_ratio,
    masked_histograms,
    rank_features,
    ring_masks,
    variance_ratio,
)


def test_llr_uses_the_floor() -> None:
    p = np.array([0.5, 0.5, 0.0])
    q = np.array([0.0, 0.5, 0.5])
    llr = log_likelihood_ratio(p, q, 0.001)
    assert np.allclose(llr, [np.log(500), 0.0, -np.log(500)])


def test_separating_feature_has_higher_variance_ratio() -> None:
    p = np.array([[0.9, 0.1, 0.0, 0.0], [0.3, 0.3, 0.2, 0.2]])
    q = np.array([[0.0, 0.1, 0.9, 0.0], [0.25, 0.25, 0.25, 0.25]])
    vr = variance_ratio(p, q, 0.001)
    assert vr[0] > 4 * vr[1]


def test_ring_has_the_requested_area() -> None:
    inner, ring = ring_masks((200, 200), (80, 80, 40, 40), 1.0)
    assert inner.sum() == 1600
    assert abs(ring.sum() - 1600) < 200
    assert not (inner & ring).any()


def test_ranking_picks_a_feature_that_separates_red_from_green() -> None:
    """A red square on green: R-G style features must outrank B alone (B is 0 everywhere)."""
    patch = np.zeros((60, 60, 3), np.uint8)
    patch[:, :] = (0, 200, 0)
    patch[20:40, 20:40] = (0, 0, 200)
    ids = tuple(range(49))
    planes = feature_bins(patch, ids, 16)
    inner, ring = ring_masks((60, 60), (20, 20, 20, 20), 1.0)
    p, q = masked_histograms(planes, inner, 16), masked_histograms(planes, ring, 16)
    top, ratios = rank_features(p, q, ids, 0.001, 3, colour_weights().astype(float), 0.6)
    b_only = next(i for i, w in enumerate(colour_weights()) if tuple(w) == (0, 0, 1))
    assert ratios[b_only] < 1e-6
    for fid in top:  # a feature separates red from green only if it weighs R and G differently
        w = colour_weights()[fid]
        assert w[0] != w[1]
    unit = (
        colour_weights()[list(top)] / np.linalg.norm(colour_weights()[list(top)], axis=1)[:, None]
    )
    cos = np.abs(unit @ unit.T) - np.eye(3)
    assert cos.max() <= 0.6 + 1e-9, "the selected features must be diverse"
