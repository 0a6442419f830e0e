"""The search window: a crop of the frame, downscaled so the target covers a fixed area.

All per-frame work (feature images, likelihood image, histograms) happens on this small patch,
never on the whole frame, which keeps the cost per update independent of resolution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Window:
    """A crop ``[x0, x1) x [y0, y1)`` of the frame resized by ``(fx, fy)`` into ``patch``."""

    x0: int
    y0: int
    fx: float
    fy: float
    patch: npt.NDArray[np.uint8]

    @cached_property
    def _origin(self) -> FloatArray:
        return np.array([self.x0, self.y0])

    @cached_property
    def _factor(self) -> FloatArray:
        return np.array([self.fx, self.fy])

    def to_patch(self, xy: FloatArray) -> FloatArray:
        """Frame pixel coordinates (..., 2) -> patch coordinates."""
        return (xy - self._origin) * self._factor

    def to_frame(self, xy: FloatArray) -> FloatArray:
        """Patch coordinates (..., 2) -> frame pixel coordinates."""
        return xy / self._factor + self._origin


def work_factor(box_w: float, box_h: float, work_area_px: int) -> float:
    """Downscale factor so that the box covers at most ``work_area_px`` pixels (never upscale)."""
    return min(1.0, math.sqrt(work_area_px / max(box_w * box_h, 1.0)))


def cut_window(
    image: npt.NDArray[np.uint8],
    centre: tuple[float, float],
    half_extent: tuple[float, float],
    factor: float,
) -> Window:
    """Crop the frame around ``centre`` (clipped to the image) and resize it by ``factor``."""
    h, w = image.shape[:2]
    cx, cy = centre
    ex, ey = half_extent
    x0 = min(max(math.floor(cx - ex), 0), w - 2)
    y0 = min(max(math.floor(cy - ey), 0), h - 2)
    x1 = min(max(math.ceil(cx + ex), x0 + 2), w)
    y1 = min(max(math.ceil(cy + ey), y0 + 2), h)
    crop = image[y0:y1, x0:x1]
    if factor >= 0.999:
        return Window(x0, y0, 1.0, 1.0, np.ascontiguousarray(crop))
    out_w = max(2, round((x1 - x0) * factor))
    out_h = max(2, round((y1 - y0) * factor))
    patch: npt.NDArray[np.uint8] = np.asarray(
        cv2.resize(crop, (out_w, out_h), interpolation=cv2.INTER_AREA), dtype=np.uint8
    )
    return Window(x0, y0, out_w / (x1 - x0), out_h / (y1 - y0), patch)


def frame_mean(image: npt.NDArray[np.uint8]) -> FloatArray:
    """Mean BGR of the frame sampled on every 8th row and column (cheap, robust to motion)."""
    return np.asarray(np.maximum(image[::8, ::8].reshape(-1, 3).mean(axis=0), 1.0))


def clamp_index(value: float, low: int, high: int) -> int:
    """``value`` truncated to an int within [low, high] (a pixel index)."""
    return int(min(max(value, low), high))
