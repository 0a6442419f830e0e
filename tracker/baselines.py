"""Baselines with the same interface as :class:`tracker.AdaptiveTracker` (paper Table 1).

- :class:`ParticleFilterTracker`: a plain particle filter, fixed RGB histogram, 120 particles.
- :class:`MeanShiftTracker`: plain mean shift (Comaniciu et al.) with a fixed RGB histogram.
- :class:`MilTracker`: OpenCV's ``TrackerMIL`` as an external peer.
- :class:`CsrtTracker`: OpenCV contrib's ``TrackerCSRT`` (only where contrib is installed).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
import numpy.typing as npt

from tracker.appearance import bhattacharyya, kernel_histograms, particle_likelihood
from tracker.features import is_grayscale
from tracker.particles import (
    propagate,
    systematic_resample,
    weighted_estimate,
)
from tracker.types import Box, Cue, TrackResult
from tracker.validation import check_box, check_image, check_same_frame
from tracker.window import Window, cut_window, work_factor

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class BaselineConfig:
    """Parameters shared by the baselines (fixed, not adaptive)."""

    particles: int = field(default=120, metadata={"ge": 4})
    rgb_bins_per_channel: int = field(default=8, metadata={"ge": 2, "le": 32})
    motion_noise_frac: float = field(default=0.1, metadata={"gt": 0.0})
    scale_noise: float = field(default=0.02, metadata={"ge": 0.0})
    omega: float = field(default=20.0, metadata={"gt": 0.0})
    search_margin_frac: float = field(default=0.75, metadata={"ge": 0.0})
    work_area_px: int = field(default=900, metadata={"ge": 64})
    sample_grid: int = field(default=16, metadata={"ge": 4})
    mean_shift_iterations: int = field(default=20, metadata={"ge": 1})


def rgb_bins(patch_bgr: npt.NDArray[np.uint8], per_channel: int) -> npt.NDArray[np.intp]:
    """Joint RGB bin index image, shape (1, H, W), values in 0..per_channel^3-1."""
    q = (patch_bgr.astype(np.intp) * per_channel) >> 8
    return ((q[:, :, 2] * per_channel + q[:, :, 1]) * per_channel + q[:, :, 0])[None]


class _FixedHistogramTracker:
    """Common state of the fixed-histogram baselines."""

    name = "fixed"

    def __init__(self, config: BaselineConfig | None = None, seed: int = 0) -> None:
        self.config = config if config is not None else BaselineConfig()
        self.rng = np.random.default_rng(seed)
        self._shape: tuple[int, ...] | None = None
        self._bins = self.config.rgb_bins_per_channel**3

    def init(self, image_bgr: npt.NDArray[np.uint8], box: Box) -> None:
        image = check_image(image_bgr)
        x, y, w, h = check_box(box, image.shape)
        self._shape = image.shape
        self._size0 = (w, h)
        self._state = np.array([x + w / 2.0, y + h / 2.0, 1.0])
        window = self._window(image, self._state)
        self._cue: Cue = "grayscale" if is_grayscale(window.patch, 1.0) else "colour"
        self._model = self._hists(window, self._state[None])[0]

    def _check(self, image_bgr: npt.NDArray[np.uint8]) -> None:
        if self._shape is None:
            raise ValueError("update: call init(image_bgr, box) first")
        check_same_frame(image_bgr, self._shape)

    def _window(self, image: npt.NDArray[np.uint8], state: FloatArray) -> Window:
        w, h = self._size0[0] * state[2], self._size0[1] * state[2]
        grow = 0.5 + self.config.search_margin_frac
        factor = work_factor(w, h, self.config.work_area_px)
        return cut_window(image, (state[0], state[1]), (w * grow, h * grow), factor)

    def _half(self, scales: FloatArray, window: Window) -> FloatArray:
        w0, h0 = self._size0
        return np.stack([scales * w0 * window.fx / 2.0, scales * h0 * window.fy / 2.0], axis=1)

    def _hists(self, window: Window, states: FloatArray) -> FloatArray:
        planes = rgb_bins(window.patch, self.config.rgb_bins_per_channel)
        centres = window.to_patch(states[:, :2])
        halves = self._half(states[:, 2], window)
        return kernel_histograms(planes, centres, halves, self.config.sample_grid, self._bins)

    def _box(self, state: FloatArray) -> Box:
        w, h = self._size0[0] * state[2], self._size0[1] * state[2]
        return (float(state[0] - w / 2), float(state[1] - h / 2), float(w), float(h))


class ParticleFilterTracker(_FixedHistogramTracker):
    """Plain colour particle filter (Nummiaro/Perez style): fixed RGB histogram, 120 particles."""

    name = "pf"

    def init(self, image_bgr: npt.NDArray[np.uint8], box: Box) -> None:
        """Start tracking the target inside ``box`` of the first frame."""
        super().init(image_bgr, box)
        self._particles = np.tile(self._state, (self.config.particles, 1))

    def update(self, image_bgr: npt.NDArray[np.uint8]) -> TrackResult:
        """Propagate with fixed noise, weight by exp(-omega s^2), estimate, resample."""
        self._check(image_bgr)
        cfg = self.config
        noise = cfg.motion_noise_frac * 0.5 * (self._size0[0] + self._size0[1]) * self._state[2]
        particles = propagate(self._particles, noise, cfg.scale_noise, (0.3, 3.0), self.rng)
        window = self._window(image_bgr, self._state)
        rho = bhattacharyya(self._hists(window, particles), self._model)
        weights = particle_likelihood(rho, cfg.omega)
        self._state = weighted_estimate(particles, weights)
        self._particles = particles[systematic_resample(weights, self.rng)]
        est_rho = float(bhattacharyya(self._hists(window, self._state[None]), self._model)[0])
        return TrackResult(self._box(self._state), est_rho, (), False, self._cue, cfg.particles)


class MeanShiftTracker(_FixedHistogramTracker):
    """Plain mean shift (Comaniciu, Ramesh & Meer) with a fixed RGB histogram and fixed size.

    Histograms are dense here (every pixel of the candidate ellipse), as in the original.
    """

    name = "meanshift"

    def init(self, image_bgr: npt.NDArray[np.uint8], box: Box) -> None:
        """Build the fixed target histogram q from the first frame."""
        super().init(image_bgr, box)
        window = self._window(image_bgr, self._state)
        planes = rgb_bins(window.patch, self.config.rgb_bins_per_channel)[0]
        centre = window.to_patch(self._state[:2])
        self._q = _dense_kernel(
            planes, centre, self._half(self._state[None, 2], window)[0], self._bins
        )[0]

    def update(self, image_bgr: npt.NDArray[np.uint8]) -> TrackResult:
        """Iterate ``y1 = sum x_i w_i / sum w_i`` with ``w_i = sqrt(q_b / p_b(y0))``."""
        self._check(image_bgr)
        cfg = self.config
        window = self._window(image_bgr, self._state)
        planes = rgb_bins(window.patch, cfg.rgb_bins_per_channel)[0]
        centre = window.to_patch(self._state[:2])
        half = self._half(self._state[None, 2], window)[0]
        for _ in range(cfg.mean_shift_iterations):
            p, region, xs, ys, inside = _dense_kernel(planes, centre, half, self._bins)
            w = np.sqrt(self._q[region] / np.maximum(p[region], 1e-12)) * inside
            if w.sum() <= 0:
                break
            moved = np.array([(w * xs).sum() / w.sum(), (w * ys).sum() / w.sum()])
            step = float(np.abs(moved - centre).max())
            centre = moved
            if step < 0.5:
                break
        self._state[:2] = window.to_frame(centre)
        p = _dense_kernel(planes, centre, half, self._bins)[0]
        rho = float(np.sqrt(p * self._q).sum())
        return TrackResult(self._box(self._state), rho, (), False, self._cue, 0)


def _dense_kernel(
    plane: npt.NDArray[np.intp], centre: FloatArray, half: FloatArray, bins: int
) -> tuple[FloatArray, npt.NDArray[np.intp], FloatArray, FloatArray, FloatArray]:
    """Epanechnikov-weighted histogram of every pixel in the ellipse (eq. 2-3).

    Returns the histogram and, for the box around it, the bin image, pixel-centre x and y
    coordinates and a 0/1 mask of the pixels inside the ellipse.
    """
    h, w = plane.shape
    x0 = min(max(int(centre[0] - half[0]), 0), w - 1)
    y0 = min(max(int(centre[1] - half[1]), 0), h - 1)
    x1 = min(max(int(np.ceil(centre[0] + half[0])), x0 + 1), w)
    y1 = min(max(int(np.ceil(centre[1] + half[1])), y0 + 1), h)
    region = plane[y0:y1, x0:x1]
    xs = np.arange(x0, x1, dtype=np.float64)[None, :] + 0.5
    ys = np.arange(y0, y1, dtype=np.float64)[:, None] + 0.5
    r2 = ((xs - centre[0]) / half[0]) ** 2 + ((ys - centre[1]) / half[1]) ** 2
    k = np.maximum(1.0 - r2, 0.0)  # eq. 3
    counts = np.bincount(region.ravel(), k.ravel(), minlength=bins).astype(np.float64)
    total = float(counts.sum())
    hist: FloatArray = counts / total if total > 0 else np.full(bins, 1.0 / bins)
    xs_full = np.broadcast_to(xs, region.shape)
    ys_full = np.broadcast_to(ys, region.shape)
    return hist, region, xs_full, ys_full, (k > 0).astype(np.float64)


MIL_MIN_SIDE_PX = 6


class _OpenCvPeer:
    """An OpenCV ``cv2.Tracker*`` behind this package's interface (external peers)."""

    name = "opencv"
    label = "Tracker"

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed
        self._shape: tuple[int, ...] | None = None

    def _create(self) -> cv2.Tracker:
        raise NotImplementedError

    def init(self, image_bgr: npt.NDArray[np.uint8], box: Box) -> None:
        """Start tracking the target inside ``box`` of the first frame."""
        image = check_image(image_bgr)
        x, y, w, h = check_box(box, image.shape)
        if w < MIL_MIN_SIDE_PX or h < MIL_MIN_SIDE_PX:
            # OpenCV 5.0's TrackerMIL never returns from init/update on boxes of 4 px or less
            raise ValueError(
                f"box: {self.label} needs width and height >= {MIL_MIN_SIDE_PX} px, "
                f"got w={w:g}, h={h:g}"
            )
        self._shape = image.shape
        cv2.setRNGSeed(self.seed)
        self._tracker = self._create()
        try:
            self._tracker.init(image, (round(x), round(y), round(w), round(h)))
        except cv2.error as err:
            raise ValueError(
                f"box: {self.label} cannot sample around (x={x:g}, y={y:g}, w={w:g}, h={h:g}); "
                "expected a box with room around it inside the image"
            ) from err
        self._cue: Cue = "grayscale" if is_grayscale(image, 1.0) else "colour"

    def update(self, image_bgr: npt.NDArray[np.uint8]) -> TrackResult:
        """Run OpenCV's update; a failed update reports the target lost."""
        if self._shape is None:
            raise ValueError("update: call init(image_bgr, box) first")
        check_same_frame(image_bgr, self._shape)
        ok, rect = self._tracker.update(image_bgr)
        if not ok:
            return TrackResult(None, 0.0, (), True, self._cue, 0)
        box = tuple(float(v) for v in rect)
        return TrackResult((box[0], box[1], box[2], box[3]), 1.0, (), False, self._cue, 0)


class MilTracker(_OpenCvPeer):
    """OpenCV ``TrackerMIL`` (Babenko et al.) with this package's interface."""

    name = "mil"
    label = "TrackerMIL"

    def _create(self) -> cv2.Tracker:
        return cv2.TrackerMIL.create()


def csrt_available() -> bool:
    """True when this OpenCV build has ``TrackerCSRT`` (opencv-contrib only)."""
    return hasattr(cv2, "TrackerCSRT")


class CsrtTracker(_OpenCvPeer):
    """OpenCV contrib ``TrackerCSRT`` (Lukezic et al., CSR-DCF), a comparison peer only.

    The project depends on opencv-python-headless, which has no CSRT; construct this only in
    an environment with opencv-contrib (see docs/benchmarks.md), else ``ValueError``.
    """

    name = "csrt"
    label = "TrackerCSRT"

    def __init__(self, seed: int = 0) -> None:
        if not csrt_available():
            raise ValueError(
                "tracker csrt: expected an OpenCV build with contrib (TrackerCSRT), "
                f"got OpenCV {cv2.__version__} without it"
            )
        super().__init__(seed)

    def _create(self) -> cv2.Tracker:
        return cv2.TrackerCSRT.create()  # type: ignore[attr-defined,unused-ignore]
