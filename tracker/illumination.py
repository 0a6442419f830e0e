"""The illumination gain: a per-channel factor that undoes a change of light before the
features are computed (not in the paper: its features are fixed linear combinations of R, G
and B, so a light that halves every channel moves every feature's histogram).

The gain is a running estimate ``gain <- (1-r) gain + r * ratio`` of the first frame's mean
over the current one, either of the whole frame (``gain_source = "frame"``, on a 1/8 grid) or
of the target's box after a trusted frame (``"target"``, with ``gain_check``: kept only if the
box, compensated with it, looks at least as much like the model as with the old gain).
:func:`compensate` multiplies the search window by it (``gain_compensation``: colour targets
only, always or never), with a dead band (``gain_deadband``) that leaves small drifts alone.
Pure functions over the immutable :class:`Gain`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from tracker.appearance import bhattacharyya, sample_index
from tracker.config import IlluminationConfig, TrackerConfig
from tracker.target_model import TargetModel, planes_of, sample_histograms
from tracker.types import Cue
from tracker.window import Window, clamp_index, frame_mean

FloatArray = npt.NDArray[np.float64]
#: The per-frame ratio is clipped to this range (a light 4x brighter or darker at most).
RATIO_RANGE = (0.25, 4.0)


@dataclass(frozen=True)
class Gain:
    """The current gain (B, G, R) and the first frame's means it is measured against."""

    gain: FloatArray
    target_mean: FloatArray  # mean BGR of the first frame's box (its core)
    frame_mean: FloatArray  # mean BGR of the first frame (1/8 grid)


def box_mean(
    window: Window, xy: FloatArray, half: FloatArray, cfg: IlluminationConfig
) -> FloatArray:
    """Mean BGR of the central part (``gain_core_frac`` of the size) of the box at ``xy``
    (frame pixels) with half size ``half`` (patch pixels), at least 1 per channel."""
    c = window.to_patch(xy[None])[0]
    half = half * cfg.gain_core_frac
    h, w = window.patch.shape[:2]
    x0, x1 = clamp_index(c[0] - half[0], 0, w - 1), clamp_index(c[0] + half[0], 1, w)
    y0, y1 = clamp_index(c[1] - half[1], 0, h - 1), clamp_index(c[1] + half[1], 1, h)
    region = window.patch[y0 : max(y1, y0 + 1), x0 : max(x1, x0 + 1)]
    return np.maximum(np.asarray(cv2.mean(region)[:3], dtype=np.float64), 1.0)


def start(target_mean: FloatArray, image: npt.NDArray[np.uint8]) -> Gain:
    """Gain 1 against the first frame (``target_mean``: :func:`box_mean` of its box)."""
    return Gain(np.ones(3), target_mean, frame_mean(image))


def applies(cfg: IlluminationConfig, cue: Cue) -> bool:
    """Whether the gain is applied to a target of this cue (``gain_compensation``)."""
    mode = cfg.gain_compensation
    return mode == "always" or (mode == "colour" and cue == "colour")


def effective(gain: FloatArray, cfg: IlluminationConfig) -> FloatArray:
    """The gain applied: a dead band (``gain_deadband``) keeps small drifts uncorrected."""
    band = cfg.gain_deadband
    return 1.0 + np.sign(gain - 1.0) * np.maximum(np.abs(gain - 1.0) - band, 0.0)


def compensate(window: Window, gain: Gain, cfg: IlluminationConfig, cue: Cue) -> Window:
    """The window with the illumination gain removed (per channel, clipped to 0..255)."""
    factor = effective(gain.gain, cfg).astype(np.float32)
    if not applies(cfg, cue) or np.abs(factor - 1.0).max() < 0.01:
        return window
    # per channel a table of the 256 levels: min(level x factor, 255) truncated, the same
    # float32 product as on the whole patch, looked up instead of computed per pixel
    lit = np.arange(256, dtype=np.uint8)[:, None] * factor[None, :]  # (256, 3)
    table = np.minimum(lit, 255, out=lit).astype(np.uint8).reshape(256, 1, 3)
    patch = np.asarray(cv2.LUT(window.patch, table), dtype=np.uint8)
    return Window(window.x0, window.y0, window.fx, window.fy, patch)


def _smoothed(gain: Gain, ratio: FloatArray, cfg: IlluminationConfig) -> FloatArray:
    rate = cfg.gain_rate
    return (1.0 - rate) * gain.gain + rate * ratio


def from_frame(gain: Gain, image: npt.NDArray[np.uint8], cfg: IlluminationConfig) -> Gain:
    """gain <- (1-r) gain + r * (first frame's mean / this frame's mean), on a 1/8 grid."""
    ratio = gain.frame_mean / frame_mean(image)
    if cfg.gain_mode == "grey":
        ratio = np.full(3, float(gain.frame_mean.sum() / frame_mean(image).sum()))
    new = _smoothed(gain, np.clip(ratio, *RATIO_RANGE), cfg)
    return Gain(new, gain.target_mean, gain.frame_mean)


def proposed(gain: Gain, current: FloatArray, cfg: IlluminationConfig) -> FloatArray:
    """gain <- (1-r) gain + r * (first-frame target mean / ``current`` target mean)."""
    ratio = np.clip(gain.target_mean / current, *RATIO_RANGE)
    if cfg.gain_mode == "grey":
        low, high = RATIO_RANGE
        ratio = np.full(3, min(max(float(gain.target_mean.sum() / current.sum()), low), high))
    return _smoothed(gain, ratio, cfg)


def rho_under_gains(
    raw: Window,
    centre: FloatArray,
    half: FloatArray,
    gains: FloatArray,
    model: TargetModel,
    cfg: TrackerConfig,
) -> FloatArray:
    """Bhattacharyya ``rho`` against the model of the box ``centre`` +- ``half`` (patch
    pixels) of the uncompensated window ``raw``, compensated with each gain of (G, 3)."""
    index = sample_index(raw.patch.shape, centre, half, cfg.filter.sample_grid)[0]
    pixels = raw.patch.reshape(-1, 3).take(index, axis=0)  # (m, 3) B, G, R
    factors = np.stack([effective(g, cfg.illumination) for g in gains])
    lit = np.clip(pixels[None] * factors[:, None, :], 0, 255).astype(np.uint8)
    planes = planes_of(lit, model.features, cfg)
    return bhattacharyya(sample_histograms(planes, cfg), model.hist(cfg.features.anchor_weight))


def from_target(
    gain: Gain,
    raw: Window,
    xy: FloatArray,
    half: FloatArray,
    model: TargetModel,
    known: FloatArray | None,
    cfg: TrackerConfig,
    cue: Cue,
) -> Gain:
    """The gain after a trusted frame, from the target's box at ``xy`` (half size ``half`` on
    the uncompensated window ``raw``).

    With ``gain_check`` the new gain is kept only if the box, compensated with it, looks at
    least as much like the model as with the old gain (``known``: the box's histogram under
    the old gain, when the caller has it).
    """
    light = cfg.illumination
    new = proposed(gain, box_mean(raw, xy, half, light), light)
    if light.gain_check and applies(light, cue):
        centre = raw.to_patch(xy[None])
        if known is None:  # both gains in one pass (each histogram as if alone)
            rho = rho_under_gains(raw, centre, half[None], np.stack([new, gain.gain]), model, cfg)
        else:
            now = bhattacharyya(known[None], model.hist(cfg.features.anchor_weight))
            rho = np.append(rho_under_gains(raw, centre, half[None], new[None], model, cfg), now)
        if rho[0] < rho[1]:
            return gain
    return Gain(new, gain.target_mean, gain.frame_mean)
