"""Feature ranking by the variance ratio of the log-likelihood ratio (paper eq. 6-8).

Collins, Liu & Leordeanu (PAMI 2005): ``p`` = object histogram / object pixel count,
``q`` = background histogram / background pixel count,
``L(i) = log(max(p(i), d) / max(q(i), d))`` with ``d = 0.001``,
``var(L; a) = sum a(i) L(i)^2 - (sum a(i) L(i))^2``,
``VR = var(L; (p+q)/2) / (var(L; p) + var(L; q))``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def masked_histograms(
    bin_images: npt.NDArray[np.intp], mask: npt.NDArray[np.bool_], bins: int
) -> FloatArray:
    """Normalised histograms of each feature plane over the pixels where ``mask`` is True.

    ``bin_images`` (k, H, W) -> (k, bins); each row sums to 1 (uniform if the mask is empty).
    """
    k = bin_images.shape[0]
    # (k, n): compress on the flat planes, the same pixels as [:, mask] at a third of the time
    values = bin_images.reshape(k, -1).compress(mask.ravel(), axis=1)
    values += (np.arange(k, dtype=values.dtype) * bins)[:, None]
    counts = np.bincount(values.ravel(), minlength=k * bins).reshape(k, bins)
    total = counts.sum(axis=1, keepdims=True).astype(np.float64)
    return np.where(total > 0, counts / np.maximum(total, 1.0), 1.0 / bins)


def log_likelihood_ratio(p: FloatArray, q: FloatArray, floor: float) -> FloatArray:
    """Eq. 8: ``L(i) = log(max(p(i), floor) / max(q(i), floor))`` (natural log)."""
    return np.log(np.maximum(p, floor) / np.maximum(q, floor))


def weighted_variance(values: FloatArray, weights: FloatArray) -> FloatArray:
    """Eq. 7: ``var(L; a) = sum a L^2 - (sum a L)^2`` along the last axis."""
    mean = (weights * values).sum(axis=-1)
    return (weights * values * values).sum(axis=-1) - mean * mean


def variance_ratio(p: FloatArray, q: FloatArray, floor: float) -> FloatArray:
    """Eq. 6: ``VR = var(L; (p+q)/2) / (var(L; p) + var(L; q))`` per feature row."""
    llr = log_likelihood_ratio(p, q, floor)
    within = weighted_variance(llr, p) + weighted_variance(llr, q)
    between = weighted_variance(llr, 0.5 * (p + q))
    return between / np.maximum(within, 1e-12)


def rank_features(
    p: FloatArray,
    q: FloatArray,
    ids: tuple[int, ...],
    floor: float,
    top: int,
    directions: FloatArray | None = None,
    max_cosine: float = 1.0,
) -> tuple[tuple[int, ...], FloatArray]:
    """The ``top`` ids with the highest variance ratio (best first) and all ratios.

    With ``directions`` (one weight vector per id), a feature whose direction has
    ``|cos| > max_cosine`` with an already chosen one is skipped while enough others remain:
    the top-VR colour features are often near-duplicates (R+2G, 2R+G, R+G), and a joint
    histogram of duplicates is no better than one feature.
    """
    ratios = variance_ratio(p, q, floor)
    order = np.argsort(-ratios, kind="stable")
    if directions is None or max_cosine >= 1.0:
        return tuple(ids[i] for i in order[:top]), ratios
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    chosen: list[int] = []
    for i in order:
        if all(abs(float(unit[i] @ unit[j])) <= max_cosine for j in chosen):
            chosen.append(int(i))
        if len(chosen) == top:
            break
    chosen += [int(i) for i in order if i not in chosen][: top - len(chosen)]
    return tuple(ids[i] for i in chosen), ratios


def ring_masks(
    shape: tuple[int, int], box: tuple[float, float, float, float], ring_area_ratio: float
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """Object mask (the box) and background mask (a ring around it) on an HxW patch.

    The ring's outer box is the object box scaled by ``sqrt(1 + ring_area_ratio)`` about its
    centre, so the ring's area is ``ring_area_ratio`` times the box's (before clipping).
    """
    h, w = shape
    x, y, bw, bh = box
    cx, cy = x + bw / 2.0, y + bh / 2.0
    grow = float(np.sqrt(1.0 + ring_area_ratio))
    ys = np.arange(h)[:, None] + 0.5
    xs = np.arange(w)[None, :] + 0.5
    inner = (np.abs(xs - cx) <= bw / 2.0) & (np.abs(ys - cy) <= bh / 2.0)
    outer = (np.abs(xs - cx) <= bw * grow / 2.0) & (np.abs(ys - cy) <= bh * grow / 2.0)
    return inner, outer & ~inner
