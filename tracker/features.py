"""The candidate feature bank (paper eq. 5) and quantised feature images.

Colour features are ``F = w1*R + w2*G + w3*B`` with ``wi in {-2..2}``: of the 124 non-zero
triples, positive multiples (e.g. (2,2,0) = 2*(1,1,0)) and sign flips (w, -w) describe the same
feature, which leaves 49 (ids 0..48).  Each feature is mapped linearly from its fixed range
``[255*sum(w<0), 255*sum(w>0)]`` onto ``bins`` histogram bins; the fixed range (not the patch's
min/max) keeps histograms of different frames comparable.

Grayscale features (R=G=B collapses every colour feature to scaled intensity): ids
``GRAY_INTENSITY`` (49), ``GRAY_GRADIENT`` (50, Sobel |gx|+|gy|), ``GRAY_CONTRAST``
(51, intensity minus its 7x7 local mean), ``GRAY_ORIENTATION`` (52, signed gradient direction
where the gradient is clear, one bin for flat pixels) and ``GRAY_LBP`` (53, rotation-invariant
uniform local binary pattern, Ojala et al. 2002: the 8 neighbours at radius 1 against the
centre, 10 codes).  The last two describe texture and shape rather than brightness, so they
separate a grey target from a background of the same grey levels.
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
GRAY_ORIENTATION = 52
GRAY_LBP = 53
GRAY_FEATURES: tuple[int, ...] = (
    GRAY_INTENSITY,
    GRAY_GRADIENT,
    GRAY_CONTRAST,
    GRAY_ORIENTATION,
    GRAY_LBP,
)
_GRAY_NAMES = {
    GRAY_INTENSITY: "intensity",
    GRAY_GRADIENT: "gradient",
    GRAY_CONTRAST: "contrast",
    GRAY_ORIENTATION: "orientation",
    GRAY_LBP: "lbp",
}
# a pixel's gradient is "clear" from |gx|+|gy| >= 16 on the 3x3 Sobel scale, i.e. a step of
# about 4 grey levels: above JPEG and sensor noise, below any edge worth describing
ORIENTATION_MIN_GRADIENT = 16.0
# LBP neighbours must exceed the centre by this many grey levels to count as "brighter", so
# that noise on flat areas does not draw random patterns
LBP_TOLERANCE = 3.0
_LBP_CODES = 10  # riu2 with 8 neighbours: 0..8 ones for uniform patterns, 9 for the rest


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
    values = pixels @ matrix  # (N, k) = ((w . rgb) - low) * bins / (range + 1)
    values += offset
    if stretch:
        low = values.min(axis=0)
        span = values.max(axis=0) - low
        values = (values - low) * (bins / np.maximum(span * (1.0 + 1.0 / bins), 1e-3))
    # clipped before truncating to int: the same bins (truncation maps (-1, 0) to 0 and
    # [bins - 1, bins) to bins - 1), on float32 and laid out (k, N) in one copy
    np.clip(values, 0, bins - 1, out=values)
    return values.T.astype(np.intp, order="C").reshape(len(ids), h, w)


def gray_feature_bins(
    patch_bgr: npt.NDArray[np.uint8], ids: tuple[int, ...], bins: int, stretch: bool = False
) -> npt.NDArray[np.intp]:
    """Bin index images of the grayscale features, shape (k, H, W).

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
        elif fid in (GRAY_GRADIENT, GRAY_ORIENTATION):
            gx = np.asarray(cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=3), dtype=np.float32)
            gy = np.asarray(cv2.Sobel(gray, cv2.CV_32F, 0, 1, ksize=3), dtype=np.float32)
            magnitude = np.abs(gx) + np.abs(gy)
            if fid == GRAY_GRADIENT:
                value = np.minimum(magnitude, 511.0) * (bins / 512.0)
            else:
                value = _orientation(gx, gy, magnitude, bins)
        elif fid == GRAY_CONTRAST:
            local = cv2.blur(gray, (7, 7))
            value = (np.clip(gray - local, -64.0, 63.0) + 64.0) * (bins / 128.0)
        elif fid == GRAY_LBP:
            value = lbp_riu2(gray) * (bins / _LBP_CODES)
        else:
            raise ValueError(f"ids: expected grayscale feature ids {GRAY_FEATURES}, got {fid}")
        planes.append(value)
    out = np.stack(planes).astype(np.intp)
    np.clip(out, 0, bins - 1, out=out)
    return out


def _orientation(
    gx: npt.NDArray[np.float32],
    gy: npt.NDArray[np.float32],
    magnitude: npt.NDArray[np.float32],
    bins: int,
) -> npt.NDArray[np.float32]:
    """Signed gradient direction in ``bins - 2`` sectors at bins 2.., flat pixels in bin 0.

    Bin 1 stays empty so that requantising to half the bins (the joint histogram) keeps the
    flat pixels apart from the first sector.
    """
    sectors = bins - 2
    angle = cv2.phase(gx, gy)  # radians in [0, 2 pi)
    sector = np.minimum(angle * (sectors / (2.0 * np.pi)), sectors - 1e-3)
    return np.where(magnitude >= ORIENTATION_MIN_GRADIENT, 2.0 + sector, 0.0).astype(np.float32)


def lbp_riu2(gray: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """Rotation-invariant uniform LBP (8 neighbours, radius 1): codes 0..9 per pixel.

    A uniform pattern (at most two 0/1 transitions around the circle) is coded by its number
    of brighter neighbours (0..8), any other pattern by 9; edge pixels copy their neighbours.
    """
    padded = cv2.copyMakeBorder(gray, 1, 1, 1, 1, cv2.BORDER_REPLICATE)
    h, w = gray.shape
    ring = ((0, 0), (0, 1), (0, 2), (1, 2), (2, 2), (2, 1), (2, 0), (1, 0))  # circular order
    bits = [padded[dy : dy + h, dx : dx + w] >= gray + LBP_TOLERANCE for dy, dx in ring]
    ones = np.sum(bits, axis=0)
    transitions = np.sum([bits[i] != bits[i - 1] for i in range(8)], axis=0)
    return np.where(transitions <= 2, ones, _LBP_CODES - 1).astype(np.float32)


def feature_bins(
    patch_bgr: npt.NDArray[np.uint8], ids: tuple[int, ...], bins: int, stretch: bool = False
) -> npt.NDArray[np.intp]:
    """Bin index images for any mix of ids: colour ids 0..48, grayscale ids 49..53."""
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


def feature_weights(feature_id: int) -> tuple[int, int, int]:
    """The (wR, wG, wB) weights of a colour feature id (0..48)."""
    r, g, b = (int(v) for v in colour_weights()[feature_id])
    return (r, g, b)
