"""Deterministic synthetic tracking sequences with exact truth (for tests and benchmarks).

A textured colour background, a landmark-like target (a sign with a coloured border and inner
pattern) moving on a smooth Lissajous path, optional global illumination change (gain and colour
cast varying over time), sensor noise, and optional frames where the target is hidden.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from companion.evaluation.sequences import Sequence


@dataclass(frozen=True)
class SynthSpec:
    """What to generate; every field has a default."""

    frames: int = 120
    width_px: int = 640
    height_px: int = 480
    target_w_px: int = 56
    target_h_px: int = 40
    amplitude_frac: float = 0.25
    period_frames: float = 200.0
    illumination: bool = True
    gain_range: tuple[float, float] = (0.55, 1.25)
    noise_sigma: float = 3.0
    hidden_frames: tuple[int, int] = (0, 0)  # [start, stop) frames without the target
    seed: int = 0


def _background(spec: SynthSpec, rng: np.random.Generator) -> npt.NDArray[np.float32]:
    small = rng.uniform(30, 220, size=(12, 16, 3)).astype(np.float32)
    bg = np.asarray(
        cv2.resize(small, (spec.width_px, spec.height_px), interpolation=cv2.INTER_CUBIC),
        dtype=np.float32,
    )
    texture = rng.normal(0, 12, size=(spec.height_px // 4, spec.width_px // 4, 3))
    bg += cv2.resize(texture.astype(np.float32), (spec.width_px, spec.height_px))
    return np.clip(bg, 0, 255)


def _target(spec: SynthSpec) -> npt.NDArray[np.float32]:
    w, h = spec.target_w_px, spec.target_h_px
    sign = np.zeros((h, w, 3), np.float32)
    sign[:] = (20, 110, 235)  # BGR orange
    b = max(2, min(w, h) // 6)
    sign[b:-b, b:-b] = (160, 60, 20)  # dark blue panel
    sign[h // 2 - b // 2 : h // 2 + b // 2 + 1, b:-b] = (240, 240, 240)  # white bar
    return sign


def centre_path(spec: SynthSpec) -> npt.NDArray[np.float64]:
    """Target centre (x, y) per frame, shape (frames, 2)."""
    t = np.arange(spec.frames, dtype=np.float64)
    phase = 2 * np.pi * t / spec.period_frames
    ax = spec.amplitude_frac * spec.width_px
    ay = spec.amplitude_frac * spec.height_px
    return np.stack(
        [spec.width_px / 2 + ax * np.sin(phase), spec.height_px / 2 + ay * np.sin(2 * phase) / 2],
        axis=1,
    )


def _gain(spec: SynthSpec, index: int) -> npt.NDArray[np.float32]:
    if not spec.illumination:
        return np.ones(3, np.float32)
    lo, hi = spec.gain_range
    g = lo + (hi - lo) * 0.5 * (1 + np.cos(2 * np.pi * index / max(spec.frames, 1)))
    cast = 1 + 0.12 * np.sin(2 * np.pi * index / max(spec.frames, 1)) * np.array([1, 0, -1])
    return (g * cast).astype(np.float32)


def generate(spec: SynthSpec) -> tuple[list[npt.NDArray[np.uint8]], npt.NDArray[np.float64]]:
    """Frames (BGR uint8) and truth boxes (frames, 4); truth rows are NaN while hidden."""
    rng = np.random.default_rng(spec.seed)
    bg = _background(spec, rng)
    sign = _target(spec)
    w, h = spec.target_w_px, spec.target_h_px
    frames, truth = [], np.full((spec.frames, 4), np.nan)
    for i, (cx, cy) in enumerate(centre_path(spec)):
        img = bg.copy()
        x0, y0 = round(cx - w / 2), round(cy - h / 2)
        if not spec.hidden_frames[0] <= i < spec.hidden_frames[1]:
            img[y0 : y0 + h, x0 : x0 + w] = sign
            truth[i] = (x0, y0, w, h)
        lit = img * _gain(spec, i) + rng.normal(0, spec.noise_sigma, img.shape)
        frames.append(np.clip(lit, 0, 255).astype(np.uint8))
    return frames, truth


def write_otb(spec: SynthSpec, folder: Path) -> Sequence:
    """Write ``img/0001.jpg...`` (quality 95) and ``groundtruth_rect.txt`` (1-based)."""
    frames, truth = generate(spec)
    (folder / "img").mkdir(parents=True, exist_ok=True)
    paths = []
    for i, frame in enumerate(frames, 1):
        path = folder / "img" / f"{i:04d}.jpg"
        cv2.imwrite(str(path), frame, [cv2.IMWRITE_JPEG_QUALITY, 95])
        paths.append(path)
    lines = [
        "0,0,0,0" if not np.isfinite(r).all() else f"{r[0] + 1:g},{r[1] + 1:g},{r[2]:g},{r[3]:g}"
        for r in truth
    ]
    (folder / "groundtruth_rect.txt").write_text("\n".join(lines) + "\n")
    return Sequence(folder.name, tuple(paths), truth)
