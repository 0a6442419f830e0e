"""A discriminative scale filter over resampled boxes (DSST; Danelljan et al., BMVC 2014).

Comparing a template at a few scales (which NCC score is highest) is a poor scale cue: the
scores of neighbouring scales differ by less than the appearance changes from frame to frame,
so the size wanders.  DSST instead learns a one-dimensional correlation filter across scales:
the box is resampled at ``S`` sizes ``a**n`` (n = -(S-1)/2 .. (S-1)/2) onto a small fixed grid,
each sample is one row of features, and the filter is trained so that correlating it with the
rows gives a Gaussian peaked at the current size.  In a new frame the peak of the response over
the rows is the size change.  With the model ``A = conj(G) F``, ``B = sum_d conj(F_d) F_d``
(FFT along the scale axis, per feature ``d``), the response is
``y = IFFT(sum_d conj(A_d) Z_d / (B + lambda))`` and both terms are running averages with rate
``eta`` (paper eq. 3-5 for the 1-D case).  The rows are real, so the spectra are kept for the
non-negative frequencies only (``rfft``), which halves the work.

Here the features are the grey levels of each resampled box, normalised to zero mean and unit
norm (so a change of light does not look like a change of size), and rows are weighted by a
Hann window over the scales as in the paper.  The same filter over pairs ``(a**n, a**-n)``
(wider and flatter, or narrower and taller, at the same area) follows the aspect ratio.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

SAMPLE_AREA_PX = 144  # each resampled box has about this many pixels (12 x 12 when square)
REGULARISATION = 0.01  # lambda
SIGMA_FACTOR = 0.25  # the Gaussian's width is SIGMA_FACTOR * sqrt(S) samples (paper: 1/4)


def factor_pairs(count: int, step: float, kind: str) -> FloatArray:
    """(S, 2) factors on (width, height) with ``f = a**n``: ``"scale"`` (f, f), ``"aspect"``
    (f, 1/f), ``"width"`` (f, 1), ``"height"`` (1, f)."""
    n = np.arange(count, dtype=np.float64) - (count - 1) / 2.0
    f = step**n
    one = np.ones_like(f)
    pairs = {"scale": (f, f), "aspect": (f, 1.0 / f), "width": (f, one), "height": (one, f)}
    if kind not in pairs:
        raise ValueError(f"kind: expected one of {', '.join(pairs)}, got {kind!r}")
    return np.stack(pairs[kind], axis=1)


def sample_size(box_wh: FloatArray) -> tuple[int, int]:
    """(width, height) of a resampled box: about ``SAMPLE_AREA_PX`` pixels, the box's shape."""
    w, h = (float(v) for v in box_wh)
    k = np.sqrt(SAMPLE_AREA_PX / max(w * h, 1e-6))
    return max(4, round(w * k)), max(4, round(h * k))


@dataclass(frozen=True)
class GreyRegion:
    """A grey crop of the full-resolution frame and the frame position of its corner."""

    image: npt.NDArray[np.uint8]
    x0: int
    y0: int


def grey_region(
    frame_bgr: npt.NDArray[np.uint8], centre: FloatArray, reach: FloatArray
) -> GreyRegion:
    """The frame within ``reach`` (x, y) of ``centre`` (clipped to the frame), in grey."""
    h, w = frame_bgr.shape[:2]
    x0 = int(min(max(np.floor(centre[0] - reach[0]), 0), w - 1))
    y0 = int(min(max(np.floor(centre[1] - reach[1]), 0), h - 1))
    x1 = int(min(max(np.ceil(centre[0] + reach[0]), x0 + 1), w))
    y1 = int(min(max(np.ceil(centre[1] + reach[1]), y0 + 1), h))
    crop = np.ascontiguousarray(frame_bgr[y0:y1, x0:x1])
    return GreyRegion(np.asarray(cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY), np.uint8), x0, y0)


def samples(
    region: GreyRegion,
    centre: FloatArray,
    box_wh: FloatArray,
    factors: FloatArray,
    size: tuple[int, int],
) -> FloatArray:
    """(S, d) rows: the box scaled by each factor pair, resampled to ``size``, normalised to
    zero mean and unit norm.

    ``centre`` and ``box_wh`` in frame pixels; ``region`` must cover the largest box.  Sampled
    from the full-resolution frame: on the tracker's downscaled window a box is ~30 px wide
    and one size step (2 %) is a fraction of a pixel, too little to tell sizes apart (the
    size found drifted to 1.4x Car4's).
    """
    sw, sh = size
    count = len(factors)
    u, v = _grid(size)
    step = np.asarray(box_wh, dtype=np.float32)[None] * factors.astype(np.float32)
    step /= np.array([sw, sh], dtype=np.float32)  # (S, 2) frame pixels per sample pixel
    map_x = np.empty((count, sh, sw), np.float32)
    map_y = np.empty((count, sh, sw), np.float32)
    map_x[:] = (float(centre[0]) - region.x0 - 0.5) + step[:, 0, None, None] * u[None, None, :]
    map_y[:] = (float(centre[1]) - region.y0 - 0.5) + step[:, 1, None, None] * v[None, :, None]
    stacked = cv2.remap(
        region.image,
        map_x.reshape(-1, sw),
        map_y.reshape(-1, sw),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
    rows = np.asarray(stacked, dtype=np.float64).reshape(count, sw * sh)
    rows -= rows.mean(axis=1, keepdims=True)
    rows /= np.maximum(np.sqrt(np.einsum("ij,ij->i", rows, rows))[:, None], 1e-6)
    return rows


@lru_cache(maxsize=16)
def _grid(size: tuple[int, int]) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """Sample pixel offsets from the centre along x and y."""
    sw, sh = size
    u = np.arange(sw, dtype=np.float32) - (sw - 1) / 2.0
    v = np.arange(sh, dtype=np.float32) - (sh - 1) / 2.0
    return u, v


@lru_cache(maxsize=8)
def _dft(count: int) -> tuple[FloatArray, FloatArray]:
    """cos and sin of the real DFT over ``count`` rows: (count // 2 + 1, count) each."""
    k = np.arange(count // 2 + 1, dtype=np.float64)[:, None]
    n = np.arange(count, dtype=np.float64)[None, :]
    angle = 2.0 * np.pi * k * n / count
    return np.cos(angle), np.sin(angle)


def _spectrum(rows: FloatArray) -> ComplexArray:
    """``rfft(rows, axis=0)`` as two small matrix products (a tenth of the time for S = 17)."""
    cos, sin = _dft(rows.shape[0])
    return np.asarray(cos @ rows - 1j * (sin @ rows), dtype=np.complex128)


@dataclass
class ScaleFilter:
    """The running numerator ``A`` and denominator ``B`` of the filter (per frequency)."""

    num: ComplexArray
    den: FloatArray
    target: ComplexArray  # conj(rFFT of the desired Gaussian response), (S // 2 + 1,)
    window: FloatArray  # Hann weights of the rows, (S, 1)

    @classmethod
    def train(cls, rows: FloatArray) -> ScaleFilter:
        """A filter from the first frame's rows (as :func:`samples` gives them)."""
        s = rows.shape[0]
        n = np.arange(s, dtype=np.float64) - (s - 1) / 2.0
        sigma = SIGMA_FACTOR * np.sqrt(s)
        gauss = np.exp(-0.5 * n * n / (sigma * sigma))
        target = np.conj(np.fft.rfft(np.fft.ifftshift(gauss)))
        window = np.hanning(s + 2)[1:-1, None]
        f = _spectrum(rows * window)
        num = target[:, None] * f
        den = (np.conj(f) * f).real.sum(axis=1)
        return cls(num, den, target, window)

    def fork(self) -> ScaleFilter:
        """A copy that learns apart from this one (:meth:`update` rebinds the arrays)."""
        return ScaleFilter(self.num, self.den, self.target, self.window)

    def spectrum(self, rows: FloatArray) -> ComplexArray:
        """The rows' spectrum as the filter uses it (Hann-weighted), for reuse."""
        return _spectrum(rows * self.window)

    def update(self, f: ComplexArray, rate: float) -> None:
        """``A <- (1-eta) A + eta conj(G) F``, ``B <- (1-eta) B + eta sum conj(F) F``.

        ``f`` is :meth:`spectrum` of the rows to learn.
        """
        self.num = (1.0 - rate) * self.num + rate * self.target[:, None] * f
        self.den = (1.0 - rate) * self.den + rate * (np.conj(f) * f).real.sum(axis=1)

    def peak(self, z: ComplexArray) -> int:
        """Row offset of the response's peak from the centre row (0 = no change).

        ``z`` is :meth:`spectrum` of the rows to read.
        """
        s = self.window.shape[0]
        spectrum = (np.conj(self.num) * z).sum(axis=1) / (self.den + REGULARISATION)
        index = int(np.argmax(np.fft.irfft(spectrum, n=s)))
        return index - s if index > s // 2 else index  # circular: the Gaussian sits at row 0
