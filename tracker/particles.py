"""Particle-filter building blocks as pure functions (filterpy style).

A particle is a row ``(x, y, s)``: centre in pixels and scale relative to the first box.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def motion_noise(
    centres: list[tuple[float, float]],
    frames: int,
    gain: float,
    low: float,
    high: float,
    initial: float | None = None,
) -> float:
    """Eq. 1: ``lambda_t = gain * (1/n) sum_{i} |u_i - u_{i-1}|`` over the last n steps.

    ``centres`` are the estimated centres, oldest first; the result is clipped to [low, high].
    With no step yet it is ``initial`` (default ``high``).
    """
    if len(centres) < 2:
        return float(initial if initial is not None else high)
    recent = np.asarray(centres[-(frames + 1) :], dtype=np.float64)
    steps = np.linalg.norm(np.diff(recent, axis=0), axis=1)
    return float(min(max(gain * steps.mean(), low), high))


def propagate(
    particles: FloatArray,
    noise_px: float,
    scale_noise: float,
    scale_range: tuple[float, float],
    rng: np.random.Generator,
) -> FloatArray:
    """Eq. 1: ``u_t = u_{t-1} + lambda_t v_t``, ``v_t ~ N(0, I)``; scale gets a log-normal step."""
    n = particles.shape[0]
    out = particles.copy()
    out[:, :2] += noise_px * rng.standard_normal((n, 2))
    out[:, 2] *= np.exp(scale_noise * rng.standard_normal(n))
    out[:, 2] = np.minimum(np.maximum(out[:, 2], scale_range[0]), scale_range[1])
    return out


def systematic_resample(weights: FloatArray, rng: np.random.Generator) -> npt.NDArray[np.intp]:
    """Indices drawn by systematic resampling: positions ``(u + i) / N`` with one ``u ~ U[0,1)``."""
    n = weights.shape[0]
    total = weights.sum()
    if not np.isfinite(total) or total <= 0:
        return np.arange(n)
    cumulative = np.cumsum(weights / total)
    cumulative[-1] = 1.0
    positions = (rng.random() + np.arange(n)) / n
    return np.searchsorted(cumulative, positions, side="right").clip(0, n - 1)


def integral_images(weight_image: npt.NDArray[np.float32]) -> FloatArray:
    """Summed-area tables of w, w*x and w*y (pixel centres), shape (3, H+1, W+1)."""
    h, w = weight_image.shape
    wi = weight_image.astype(np.float64)
    xs = np.arange(w, dtype=np.float64)[None, :] + 0.5
    ys = np.arange(h, dtype=np.float64)[:, None] + 0.5
    # (3, H+1, W+1), zero first row/column: one table per image (the same sums as one
    # three-channel table, without interleaving the channels and back)
    return np.stack([cv2.integral(im, sdepth=cv2.CV_64F) for im in (wi, wi * xs, wi * ys)])


def window_sums(
    tables: FloatArray, centres: FloatArray, half_sizes: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Sums of the tabled images over each centre's box, (3, P), and the box areas (P,) in px."""
    _, hp1, wp1 = tables.shape
    p = len(centres)
    box = np.empty((p, 4))
    np.subtract(centres, half_sizes, out=box[:, :2])
    np.add(centres, half_sizes, out=box[:, 2:])
    corners = np.rint(box, out=box).astype(np.intp)
    np.minimum(
        np.maximum(corners, 0, out=corners), (wp1 - 1, hp1 - 1, wp1 - 1, hp1 - 1), out=corners
    )
    x0, y0, x1, y1 = corners.T
    r0, r1 = y0 * wp1, y1 * wp1
    index = np.concatenate([r1 + x1, r0 + x1, r1 + x0, r0 + x0])
    # one take on the flat axis for the four corners: [:, y, x] four times, faster
    at = tables.reshape(len(tables), -1).take(index, axis=1)
    sums = at[:, :p] - at[:, p : 2 * p] - at[:, 2 * p : 3 * p] + at[:, 3 * p :]
    return sums, ((x1 - x0) * (y1 - y0)).astype(np.float64)


def mean_shift(
    tables: FloatArray, centres: FloatArray, half_sizes: FloatArray, iterations: int
) -> FloatArray:
    """Move each centre to the weighted mean of the weight image inside its box.

    ``y_new = sum_i w_i x_i / sum_i w_i`` over the box window: the mean-shift step for the
    Epanechnikov kernel, whose shadow is flat (the box stands in for the inscribed ellipse so the
    sums come from integral images in O(1) per centre).  Centres with no weight stay put.
    """
    c = centres.astype(np.float64).copy()
    for _ in range(iterations):
        sums, _ = window_sums(tables, c, half_sizes)
        np.divide(sums[1:], sums[0], out=c.T, where=sums[0] > 1e-9)  # (x, y) where weighted
    return c


def weighted_estimate(particles: FloatArray, weights: FloatArray) -> FloatArray:
    """CONDENSATION estimate ``E[x] = sum_n pi_n s_n`` with ``pi_n = w_n / sum_j w_j``."""
    total = weights.sum()
    if total <= 0:
        return particles.mean(axis=0)
    return (weights[:, None] * particles).sum(axis=0) / total
