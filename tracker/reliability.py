"""Per-pixel reliability of the template (CSR-DCF's spatial reliability map, issue 22).

A template matched by plain NCC gives every pixel of the box the same say, so whatever in
the box has the most texture carries the match: on Coke the white logo, which the turning
can carries to its right edge, and the fingers above the can; the box follows them 8-12 px
off the can's centre.  Lukezic et al. (CSR-DCF, CVPR 2017) weight the filter by a spatial
reliability map: the posterior that a pixel belongs to the target, from the colour
histograms of the target and of its surroundings, times a central prior.

Here the likelihood image the particle filter already computes is the evidence: its value at
a pixel is the mean over the selected features of ``L = log(p / q)`` (target histogram over
ring histogram), so ``sigmoid(L) = p / (p + q)`` is the histograms' foreground probability
with equal priors.  The prior is CSR-DCF's: an Epanechnikov kernel ``1 - r^2`` over the box
(``r`` = 1 on the inscribed ellipse), clipped to [0.5, 0.9] (the box's centre is probably the
target, its corners are undecided, nothing is ruled out by position alone).  The posterior

    ``m = s k / (s k + (1 - s)(1 - k))``, ``s = sigmoid(L)``, ``k`` the prior

is the pixel's weight in the match (:func:`tracker.template.weighted_response`).  Pixels whose
colour the ring explains as well as the box (skin of a hand that reaches outside the box, a
logo whose white is also in the background) get little weight; the target's own colour most.
Where fewer than ``MIN_RELIABLE`` of the box's pixels have a posterior above 0.5, the colour
histograms do not separate the target here (a grey target, a target like its background) and
the map is uniform: plain NCC, as without it.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

Weights = npt.NDArray[np.float32]

PRIOR_RANGE = (0.5, 0.9)  # CSR-DCF's clip of the Epanechnikov prior
# Below this share of reliable pixels the map cannot be told from noise: a uniform map.
MIN_RELIABLE = 0.25


def prior(size: tuple[int, int]) -> Weights:
    """The central prior for a template of ``size`` = (w, h): Epanechnikov over the box's
    inscribed ellipse, clipped to ``PRIOR_RANGE``."""
    w, h = size
    u = (np.arange(w) + 0.5) / w * 2.0 - 1.0
    v = (np.arange(h) + 0.5) / h * 2.0 - 1.0
    r2 = u[None, :] ** 2 + v[:, None] ** 2
    return np.clip(1.0 - r2, *PRIOR_RANGE).astype(np.float32)


def reliability(llr: npt.NDArray[np.float32], central: Weights) -> Weights:
    """The posterior that each pixel of the box belongs to the target, from the likelihood
    image cut to the template's size (``llr``) and the prior ``central``; uniform (ones) where
    too few pixels are reliable (``MIN_RELIABLE``)."""
    s = 1.0 / (1.0 + np.exp(-np.asarray(llr, dtype=np.float32)))
    import os
    if os.environ.get("REL_PRIOR") == "flat":
        central = np.full_like(central, 0.5)
    fg = s * central
    posterior = fg / np.maximum(fg + (1.0 - s) * (1.0 - central), 1e-6)
    if float(np.mean(posterior > 0.5)) < MIN_RELIABLE:
        return np.ones_like(central)
    import os
    mode = os.environ.get("REL_MODE", "soft")
    if mode == "binary":
        return (posterior > 0.5).astype(np.float32)
    if mode == "half":
        return (0.5 + 0.5 * posterior).astype(np.float32)
    if mode == "floor":
        return np.maximum(posterior, 0.5).astype(np.float32)
    return posterior.astype(np.float32)
