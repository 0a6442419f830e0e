"""Kernel-weighted histograms and the Bhattacharyya likelihood (paper eq. 2-4).

Each candidate box is sampled on a fixed ``n x n`` grid of normalised offsets in [-1, 1]^2
(points outside the inscribed ellipse are dropped); each sample carries the Epanechnikov weight
``k(r^2) = 1 - r^2`` (eq. 3).  Sampling a fixed grid makes the cost independent of the box size
and lets every particle (with its own scale) be evaluated in one vectorised ``np.bincount``.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntT = TypeVar("IntT", bound=np.integer[Any])


@lru_cache(maxsize=8)
def epanechnikov_grid(n: int) -> tuple[FloatArray, FloatArray]:
    """Offsets (m, 2) in [-1, 1] and weights (m,) = 1 - r^2 for the points with r^2 < 1."""
    t = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    gx, gy = np.meshgrid(t, t)
    r2 = gx * gx + gy * gy
    inside = r2 < 1.0
    offsets = np.stack([gx[inside], gy[inside]], axis=1)
    return offsets, 1.0 - r2[inside]  # eq. 3: k(u) = 1 - ||u||^2 inside the unit circle


def sample_index(
    shape: tuple[int, ...], centres: FloatArray, half_sizes: FloatArray, grid: int
) -> npt.NDArray[np.intp]:
    """Flat pixel indices (P, m) of each candidate's kernel sample points on an image of
    ``shape`` (H, W, ...); ``centres`` (P, 2) and ``half_sizes`` (P, 2) in pixels (x, y);
    points outside take the nearest edge pixel."""
    ox, oy = _grid_axes(grid)
    h, w = shape[:2]
    xs = centres[:, None, 0] + ox * half_sizes[:, None, 0]
    ys = centres[:, None, 1] + oy * half_sizes[:, None, 1]
    xi, index = xs.astype(np.intp), ys.astype(np.intp)
    np.minimum(np.maximum(xi, 0, out=xi), w - 1, out=xi)
    np.minimum(np.maximum(index, 0, out=index), h - 1, out=index)
    index *= w
    index += xi
    return index


@lru_cache(maxsize=8)
def _grid_axes(grid: int) -> tuple[FloatArray, FloatArray]:
    """The grid's x and y offsets as two contiguous (1, m) rows (read-only)."""
    offsets, _ = epanechnikov_grid(grid)
    axes = np.ascontiguousarray(offsets[:, 0])[None], np.ascontiguousarray(offsets[:, 1])[None]
    for a in axes:
        a.flags.writeable = False
    return axes


def sample_bins(
    bin_images: npt.NDArray[IntT], centres: FloatArray, half_sizes: FloatArray, grid: int
) -> npt.NDArray[IntT]:
    """Bin indices at each candidate's kernel sample points, shape (k, P, m).

    ``bin_images`` (k, H, W); ``centres`` (P, 2) and ``half_sizes`` (P, 2) in patch pixels
    (x, y); points outside the patch take the nearest edge pixel.
    """
    k = bin_images.shape[0]
    index = sample_index(bin_images.shape[1:], centres, half_sizes, grid)
    # take along the flat axis: the same gather as ``[:, index]``, 5-6x faster in numpy
    return bin_images.reshape(k, -1).take(index, axis=1)


def histograms_from_samples(samples: npt.NDArray[np.intp], grid: int, bins: int) -> FloatArray:
    """Eq. 2: normalised kernel-weighted histograms from sampled bins (k, P, m) -> (P, k, bins).

    ``q_b = g sum_i k(||(h - u_i)/l||^2) delta(b(u_i) - b)``, ``g = 1 / sum_i k(...)``.
    """
    _, weights = epanechnikov_grid(grid)
    k, p, _ = samples.shape
    index = samples + _slots(k, p, bins)
    hist = np.bincount(index.ravel(), _tiled_weights(grid, k * p), minlength=p * k * bins)
    return hist.reshape(p, k, bins) / weights.sum()


@lru_cache(maxsize=32)
def _slots(k: int, p: int, bins: int) -> npt.NDArray[np.intp]:
    """(k, P, 1) first bin of each (feature, candidate) histogram in the flat count (read-only)."""
    slot = (np.arange(p, dtype=np.intp)[None, :] * k + np.arange(k)[:, None]) * bins
    out = slot[:, :, None]
    out.flags.writeable = False
    return out


@lru_cache(maxsize=32)
def _tiled_weights(grid: int, copies: int) -> FloatArray:
    """The kernel weights of :func:`epanechnikov_grid` repeated ``copies`` times (read-only)."""
    tiled = np.tile(epanechnikov_grid(grid)[1], copies)
    tiled.flags.writeable = False
    return tiled


def kernel_histograms(
    bin_images: npt.NDArray[np.intp],
    centres: FloatArray,
    half_sizes: FloatArray,
    grid: int,
    bins: int,
) -> FloatArray:
    """Eq. 2 for each candidate box: (P, k, bins) histograms, each summing to 1."""
    return histograms_from_samples(sample_bins(bin_images, centres, half_sizes, grid), grid, bins)


def bhattacharyya(hists: FloatArray, model: FloatArray) -> FloatArray:
    """Eq. 4: coefficient ``rho = sum sqrt(p q)``, averaged over the k features -> (P,)."""
    per_feature = np.sqrt(hists * model[None]).sum(axis=-1)
    return per_feature.sum(axis=-1) / per_feature.shape[-1]  # the mean, without its overhead


def bhattacharyya_distance(rho: FloatArray) -> FloatArray:
    """Eq. 4: ``s = sqrt(1 - rho)``."""
    return np.sqrt(np.maximum(1.0 - rho, 0.0))


def particle_likelihood(rho: FloatArray, omega: float) -> FloatArray:
    """``q(c|u) ~ exp(-omega * s^2)`` with ``s^2 = 1 - rho``."""
    return np.exp(-omega * np.maximum(1.0 - rho, 0.0))


def joint_planes(
    bin_images: npt.NDArray[np.intp], bins: int, joint_bins: int
) -> npt.NDArray[np.intp]:
    """Fold k feature planes (values < bins) into one joint index plane: (k, ...) -> (1, ...).

    Each feature is requantised to ``joint_bins`` levels; the joint histogram has
    ``joint_bins**k`` bins and keeps the correlation between features that marginals lose.
    Works on whole planes (k, H, W) or on samples (k, P, m).
    """
    level = (np.arange(bins, dtype=np.intp) * joint_bins) // bins  # bin -> joint level
    out = level.take(bin_images[0])
    for plane in bin_images[1:]:
        out *= joint_bins
        out += level.take(plane)
    return out[None]
