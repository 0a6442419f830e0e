"""The candidate feature bank (paper eq. 5) and quantised feature images.

Colour features are ``F = w1*R + w2*G + w3*B`` with ``wi in {-2..2}``: of the 124 non-zero
triples, positive multiples (e.g. (2,2,0) = 2*(1,1,0)) and sign flips (w, -w) describe the same
feature, which leaves 49 (ids 0..48).  Each feature is mapped linearly from its fixed range
``[255*sum(w<0), 255*sum(w>0)]`` onto ``bins`` histogram bins; the fixed range (not the patch's
min/max) keeps histograms of different frames comparable.

Grayscale fallback (R=G=B collapses every colour feature to scaled intensity): ids
``GRAY_INTENSITY`` (49), ``GRAY_GRADIENT`` (50, Sobel |gx|+|gy|) and ``GRAY_CONTRAST``
(51, intensity minus its 7x7 local mean).
"""

from __future__ import annotations

import math
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt

GRAY_INTENSITY = 49
GRAY_GRADIENT = 50
GRAY_CONTRAST = 51
GRAY_FEATURES: tuple[int, ...] = (GRAY_INTENSITY, GRAY_GRADIENT, GRAY_CONTRAST)
_GRAY_NAMES = {GRAY_INTENSITY: "intensity", GRAY_GRADIENT: "gradient", GRAY_CONTRAST: "contrast"}


@lru_cache(maxsize=1)
def colour_weights() -> npt.NDArray[np.int64]:
    """The 49 distinct (wR, wG, wB) triples, shape (49, 3), in a fixed order."""
    seen: list[tuple[int, int, int]] = []
    for r in range(-2, 3):
        for g in range(-2, 3):
            for b in range(-2, 3):
                if (r, g, b) == (0, 0, 0):
                    continue
                d = math.gcd(math.gcd(abs(r), abs(g)), abs(b))
                w = (r // d, g // d, b // d)
                first = next(v for v in w if v != 0)
                if first < 0:  # w and -w are one feature
                    w = (-w[0], -w[1], -w[2])
                if w not in seen:
                    seen.append(w)
    return np.array(seen, dtype=np.int64)


def feature_name(feature_id: int) -> str:
    """Human-readable name, e.g. ``"1R-2G+0B"`` or ``"gray:gradient"``."""
    if feature_id in _GRAY_NAMES:
        return "gray:" + _GRAY_NAMES[feature_id]
    r, g, b = (int(v) for v in colour_weights()[feature_id])
    return f"{r}R{g:+d}G{b:+d}B"


@lru_cache(maxsize=64)
def _colour_mapping(ids: tuple[int, ...], bins: int) -> tuple[npt.NDArray[np.float32], ...]:
    """BGR weight matrix (3, k), offsets and scales mapping feature values onto bins."""
    w_rgb = colour_weights()[list(ids)].astype(np.float64)
    w_bgr = w_rgb[:, ::-1]
    low = 255.0 * np.minimum(w_rgb, 0).sum(axis=1)
    high = 255.0 * np.maximum(w_rgb, 0).sum(axis=1)
    scale = bins / (high - low + 1.0)  # bin = floor((F - low) * bins / (range + 1))
    matrix = (w_bgr * scale[:, None]).T.astype(np.float32)
    offset = (-low * scale).astype(np.float32)
    return matrix, offset


def colour_feature_bins(
    patch_bgr: npt.NDArray[np.uint8], ids: tuple[int, ...], bins: int, stretch: bool = False
) -> npt.NDArray[np.intp]:
    """Bin index images of colour features, shape (k, H, W), values in 0..bins-1.

    With ``stretch`` each feature is mapped from the patch's own [min, max] instead of its
    fixed range, which makes the bins invariant to a global gain (illumination level).
    """
    matrix, offset = _colour_mapping(ids, bins)
    h, w = patch_bgr.shape[:2]
    pixels = patch_bgr.reshape(-1, 3).astype(np.float32)
    values = pixels @ matrix + offset  # (N, k) = ((w . rgb) - low) * bins / (range + 1)
    if stretch:
        low = values.min(axis=0)
        span = values.max(axis=0) - low
        values = (values - low) * (bins / np.maximum(span * (1.0 + 1.0 / bins), 1e-3))
    out = values.astype(np.intp).T.reshape(len(ids), h, w)
    np.minimum(np.maximum(out, 0, out=out), bins - 1, out=out)
    return out


def gray_feature_bins(
    patch_bgr: npt.NDArray[np.uint8], ids: tuple[int, ...], bins: int, stretch: bool = False
) -> npt.NDArray[np.intp]:
    """Bin index images of the grayscale fallback features, shape (k, H, W).

    With ``stretch`` the grey levels are first stretched to the patch's [min, max].
    """
    gray = patch_bgr[:, :, 1].astype(np.float32)
    if stretch:
        low = float(gray.min())
        gray = (gray - low) * (255.0 / max(float(gray.max()) - low, 1.0))
    planes = []
    for fid in ids:
        if fid == GRAY_INTENSITY:
            value = gray * (bins / 256.0)
        elif fid == GRAY_GRADIENT:
            gx = cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=3)
            gy = cv2.Sobel(gray, cv2.CV_32F, 0, 1, ksize=3)
            value = np.minimum(np.abs(gx) + np.abs(gy), 511.0) * (bins / 512.0)
        elif fid == GRAY_CONTRAST:
            local = cv2.blur(gray, (7, 7))
            value = (np.clip(gray - local, -64.0, 63.0) + 64.0) * (bins / 128.0)
        else:
            raise ValueError(f"ids: expected grayscale feature ids {GRAY_FEATURES}, got {fid}")
        planes.append(value)
    out = np.stack(planes).astype(np.intp)
    np.clip(out, 0, bins - 1, out=out)
    return out


def feature_bins(
    patch_bgr: npt.NDArray[np.uint8], ids: tuple[int, ...], bins: int, stretch: bool = False
) -> npt.NDArray[np.intp]:
    """Bin index images for any mix of ids: colour ids 0..48, grayscale ids 49..51."""
    if all(i < GRAY_INTENSITY for i in ids):
        return colour_feature_bins(patch_bgr, ids, bins, stretch)
    if all(i in _GRAY_NAMES for i in ids):
        return gray_feature_bins(patch_bgr, ids, bins, stretch)
    colour = [i for i in ids if i < GRAY_INTENSITY]
    gray = [i for i in ids if i >= GRAY_INTENSITY]
    parts = {
        **dict(
            zip(colour, colour_feature_bins(patch_bgr, tuple(colour), bins, stretch), strict=True)
        ),
        **dict(zip(gray, gray_feature_bins(patch_bgr, tuple(gray), bins, stretch), strict=True)),
    }
    return np.stack([parts[i] for i in ids])


def is_grayscale(patch_bgr: npt.NDArray[np.uint8], tolerance: float) -> bool:
    """True when the channels agree: mean |B-G| + |G-R| <= tolerance (grey levels)."""
    p = patch_bgr.astype(np.int16)
    diff = np.abs(p[:, :, 0] - p[:, :, 1]) + np.abs(p[:, :, 1] - p[:, :, 2])
    return float(diff.mean()) <= tolerance
