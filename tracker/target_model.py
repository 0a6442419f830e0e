"""The target's appearance model: selected features, their likelihood image, kernel histograms.

:func:`rank` is the paper's feature selection (eq. 6-8, Collins et al.): the candidate
features ranked by variance ratio between the target box and a ring around it, the top ones
kept with their log-likelihood ratios.  :func:`likelihood` back-projects those ratios on the
search window (fig. 5); :func:`kernel` gives the Epanechnikov-weighted histograms (eq. 2-3)
that the Bhattacharyya coefficient (eq. 4) compares with :meth:`TargetModel.hist`.  Built on
:mod:`tracker.appearance`, :mod:`tracker.ranking` and :mod:`tracker.features`; everything here
is a pure function of its arguments.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from tracker.appearance import (
    bhattacharyya,
    histograms_from_samples,
    joint_planes,
    sample_bins,
)
from tracker.config import TrackerConfig
from tracker.features import colour_weights, feature_bins
from tracker.particles import window_sums
from tracker.ranking import log_likelihood_ratio, masked_histograms, rank_features, ring_masks
from tracker.types import Cue
from tracker.window import Window

FloatArray = npt.NDArray[np.float64]
BinPlanes = npt.NDArray[np.intp]
Counted = tuple[BinPlanes, int]  # :func:`counted` planes and their number of bins
_NEIGHBOURS = np.array([(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy], float)


@dataclass(frozen=True)
class TargetModel:
    """The appearance model for the selected features."""

    features: tuple[int, ...]
    llr: FloatArray  # (k, bins) log-likelihood ratio, eq. 8
    first: FloatArray  # (k, bins) kernel histograms on the first frame
    recent: FloatArray  # (k, bins) running kernel histograms of recent estimates
    rho_ref: float  # rho of the first frame's target against the model
    rho_bg: float  # mean rho of the background around the target against the model

    def hist(self, anchor: float) -> FloatArray:
        """The model histograms: ``anchor`` x the first frame's + the rest x the recent ones."""
        return anchor * self.first + (1.0 - anchor) * self.recent

    def learnt(self, hist: FloatArray, rate: float) -> TargetModel:
        """The model with ``hist`` (an estimate's histograms) learnt into ``recent``."""
        recent = (1.0 - rate) * self.recent + rate * hist
        return TargetModel(self.features, self.llr, self.first, recent, self.rho_ref, self.rho_bg)

    def confidence(self, rho: FloatArray) -> FloatArray:
        """Calibrated confidence: 0 at the background's similarity, 1 at the first frame's."""
        return np.minimum(
            np.maximum((rho - self.rho_bg) / (self.rho_ref - self.rho_bg), 0.0), 1.0
        )


@dataclass(frozen=True)
class FirstFrame:
    """What the first frame fixed for the model: the cue, the candidate features, the
    search window and box (centre and half size on that window's patch) and the object
    histograms of every candidate there (``p``: eq. 6's anchor, None until the first rank)."""

    cue: Cue
    candidates: tuple[int, ...]
    window: Window
    centre: FloatArray  # (1, 2) on the first window's patch
    p: FloatArray | None = None


def planes_of(
    patch: npt.NDArray[np.uint8], features: tuple[int, ...], cfg: TrackerConfig
) -> BinPlanes:
    """Bin images (k, H, W) of ``features`` on a patch."""
    return feature_bins(patch, features, cfg.features.bins, cfg.features.stretch_features)


def counted(planes: BinPlanes, cfg: TrackerConfig) -> Counted:
    """What kernel histograms count, from bin planes (k, ...) of whole images or of samples:
    the joint index plane (``appearance = "joint"``: one plane, ``joint_bins**k`` bins) or
    the k planes (``bins`` each).  Folding a window's planes once per frame, before
    sampling, gives the same histograms as folding every particle's samples, with a third
    of the sampling."""
    f = cfg.features
    if f.appearance == "joint":
        return joint_planes(planes, f.bins, f.joint_bins), f.joint_bins ** planes.shape[0]
    return planes, f.bins


def sample_histograms(samples: BinPlanes, cfg: TrackerConfig) -> FloatArray:
    """Kernel histograms from bins sampled on the kernel grid, (k, P, m) -> (P, ...):
    one joint histogram (``appearance = "joint"``) or one per feature."""
    folded, nbins = counted(samples, cfg)
    return histograms_from_samples(folded, cfg.filter.sample_grid, nbins)


def kernel(
    planes: Counted, centres: FloatArray, halves: FloatArray, cfg: TrackerConfig
) -> FloatArray:
    """Kernel histograms (eq. 2) of the boxes ``centres`` +- ``halves`` (patch pixels) on
    :func:`counted` planes."""
    folded, nbins = planes
    grid = cfg.filter.sample_grid
    return histograms_from_samples(sample_bins(folded, centres, halves, grid), grid, nbins)


def likelihood(
    patch: npt.NDArray[np.uint8], model: TargetModel, cfg: TrackerConfig
) -> tuple[Counted, npt.NDArray[np.float32]]:
    """The selected features' :func:`counted` planes and their mean back-projected LLR
    image."""
    planes = planes_of(patch, model.features, cfg)
    llr = model.llr
    image = llr[0].take(planes[0])  # take: the same gather as llr[0][planes[0]], faster
    for i in range(1, len(planes)):
        image = image + llr[i].take(planes[i])
    return counted(planes, cfg), (image / len(planes)).astype(np.float32)


def llr_factor(
    lik: npt.NDArray[np.float32], centres: FloatArray, halves: FloatArray, cfg: TrackerConfig
) -> FloatArray:
    """``exp(llr_gain * (vote - max over particles))``: the likelihood image's vote.

    The vote is the mean LLR in the box minus, with ``llr_vote = "contrast"``, the mean LLR
    in the ring around it (the ranking's ring, ``ring_area_ratio``).  The box mean alone
    favours boxes smaller than the target (its most distinctive pixels); the contrast drops
    both when background enters the box and when target enters the ring.
    """
    table: FloatArray = np.asarray(cv2.integral(lik, sdepth=cv2.CV_64F), np.float64)[None]
    sums, area = window_sums(table, centres, halves)
    vote = sums[0] / np.maximum(area, 1.0)
    if cfg.filter.llr_vote == "contrast":
        grow = float(np.sqrt(1.0 + cfg.features.ring_area_ratio))
        outer, outer_area = window_sums(table, centres, halves * grow)
        vote = vote - (outer[0] - sums[0]) / np.maximum(outer_area - area, 1.0)
    return np.exp(cfg.filter.llr_gain * (vote - vote.max()))


def _candidate_histograms(
    window: Window, centre: FloatArray, half: FloatArray, first: FirstFrame, cfg: TrackerConfig
) -> tuple[FloatArray, FloatArray]:
    """Object (box) and background (ring) histograms of every candidate feature."""
    f = cfg.features
    patch_box = (centre[0] - half[0], centre[1] - half[1], 2 * half[0], 2 * half[1])
    inner, ring = ring_masks(window.patch.shape[:2], patch_box, f.ring_area_ratio)
    if first.cue == "colour" and not f.stretch_features:  # per pixel: box and ring only
        used = inner | ring
        inner, ring = inner[used][None], ring[used][None]
        planes = feature_bins(window.patch[used][None], first.candidates, f.bins)
    else:  # the grey features are neighbourhood operators: the whole window
        planes = feature_bins(window.patch, first.candidates, f.bins, f.stretch_features)
    return masked_histograms(planes, inner, f.bins), masked_histograms(planes, ring, f.bins)


def rank(
    window: Window,
    centre: FloatArray,
    half: FloatArray,
    first: FirstFrame,
    first_half: FloatArray,
    trusted: bool,
    cfg: TrackerConfig,
) -> tuple[TargetModel, FloatArray]:
    """Select the top features by variance ratio (eq. 6-8) and rebuild the model around the
    box ``centre`` +- ``half`` on ``window``; returns the model and the first frame's object
    histograms (``first.p``, or this box's when ``first.p`` is None).

    The object histograms mix the first frame's with the current box's (``anchor_weight``);
    when the estimate is not ``trusted`` (low confidence) only the first frame's are used,
    so a drifting estimate cannot redefine the target.  ``first_half`` is the first box's
    half size on the first window at the current aspect.
    """
    f = cfg.features
    p_now, q = _candidate_histograms(window, centre, half, first, cfg)
    p_first = p_now if first.p is None else first.p
    anchor = f.anchor_weight if trusted else 1.0
    p = anchor * p_first + (1.0 - anchor) * p_now
    directions = colour_weights().astype(np.float64) if first.cue == "colour" else None
    top, _ = rank_features(
        p, q, first.candidates, f.loglik_floor, f.top_features, directions, f.max_feature_cosine
    )
    rows = [first.candidates.index(i) for i in top]
    llr = log_likelihood_ratio(p[rows], q[rows], f.loglik_floor)
    first_planes = counted(planes_of(first.window.patch, top, cfg), cfg)
    first_hist = kernel(first_planes, first.centre, first_half, cfg)[0]
    sel = counted(planes_of(window.patch, top, cfg), cfg)
    recent = kernel(sel, centre[None], half[None], cfg)[0] if trusted else first_hist
    model = f.anchor_weight * first_hist + (1.0 - f.anchor_weight) * recent
    around = centre[None] + _NEIGHBOURS * 2.0 * half[None]
    halves = np.repeat(half[None], len(around), axis=0)
    rho_bg = float(bhattacharyya(kernel(sel, around, halves, cfg), model).mean())
    rho_ref = float(bhattacharyya(first_hist[None], model)[0])
    found = TargetModel(top, llr, first_hist, recent, rho_ref, min(rho_bg, rho_ref - 0.05))
    return found, p_first
