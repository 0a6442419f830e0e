"""Line plots drawn with OpenCV (no plotting dependency): axes, ticks, legend, PNG-ready."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

Image = npt.NDArray[np.uint8]
#: BGR colours for successive series (colour-blind friendly Okabe-Ito palette).
PALETTE = (
    (178, 114, 0),
    (0, 159, 230),
    (115, 158, 0),
    (167, 121, 204),
    (0, 94, 213),
    (66, 228, 240),
    (233, 180, 86),
)
_FONT = cv2.FONT_HERSHEY_SIMPLEX


@dataclass(frozen=True)
class Series:
    """One line: its label and (x, y) values (NaN y leaves a gap)."""

    label: str
    x: npt.NDArray[np.float64]
    y: npt.NDArray[np.float64]


def _ticks(lo: float, hi: float, count: int = 5) -> npt.NDArray[np.float64]:
    span = max(hi - lo, 1e-9)
    raw = span / count
    step = 10 ** np.floor(np.log10(raw))
    step *= min((m for m in (1, 2, 5, 10) if m * step >= raw), default=10)
    return np.arange(np.ceil(lo / step) * step, hi + step * 0.5, step)


def line_plot(
    series: Sequence[Series],
    title: str,
    x_label: str,
    y_label: str,
    y_range: tuple[float, float] | None = None,
    size: tuple[int, int] = (640, 400),
) -> Image:
    """Render the series into a white BGR image of ``size`` (width, height)."""
    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    left, right, top, bottom = 60, 15, 30, 45
    xs = np.concatenate([s.x for s in series]) if series else np.zeros(1)
    ys = np.concatenate([s.y[np.isfinite(s.y)] for s in series]) if series else np.zeros(1)
    x0, x1 = float(np.min(xs)), float(np.max(xs)) if xs.size else 1.0
    if y_range is None:
        y_range = (0.0, float(np.max(ys)) * 1.05 if ys.size and np.max(ys) > 0 else 1.0)
    y0, y1 = y_range
    x1 = x1 if x1 > x0 else x0 + 1.0

    def px(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]) -> npt.NDArray[np.int32]:
        u = left + (x - x0) / (x1 - x0) * (w - left - right)
        v = h - bottom - (np.clip(y, y0, y1) - y0) / (y1 - y0) * (h - top - bottom)
        return np.stack([u, v], axis=-1).round().astype(np.int32)

    for t in _ticks(y0, y1):
        (u, v) = px(np.array([x0]), np.array([t]))[0]
        cv2.line(img, (left, int(v)), (w - right, int(v)), (225, 225, 225), 1)
        cv2.putText(img, f"{t:g}", (5, int(v) + 4), _FONT, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
    for t in _ticks(x0, x1, 6):
        (u, v) = px(np.array([t]), np.array([y0]))[0]
        cv2.line(img, (int(u), h - bottom), (int(u), h - bottom + 4), (60, 60, 60), 1)
        cv2.putText(
            img, f"{t:g}", (int(u) - 10, h - bottom + 18), _FONT, 0.4, (60, 60, 60), 1, cv2.LINE_AA
        )
    cv2.rectangle(img, (left, top), (w - right, h - bottom), (60, 60, 60), 1)
    for i, s in enumerate(series):
        colour = PALETTE[i % len(PALETTE)]
        pts = px(s.x, s.y)
        finite = np.isfinite(s.y)
        for a, b, ok in zip(pts[:-1], pts[1:], finite[:-1] & finite[1:], strict=True):
            if ok:
                cv2.line(
                    img, tuple(int(v) for v in a), tuple(int(v) for v in b), colour, 2, cv2.LINE_AA
                )
        ly = top + 16 + 16 * i
        cv2.line(img, (w - right - 150, ly - 4), (w - right - 130, ly - 4), colour, 2)
        cv2.putText(img, s.label, (w - right - 125, ly), _FONT, 0.42, (30, 30, 30), 1, cv2.LINE_AA)
    cv2.putText(img, title, (left, 20), _FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, x_label, (w // 2 - 40, h - 8), _FONT, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, y_label, (5, top - 8 + 0), _FONT, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return img


def likelihood_panel(
    frame: Image,
    box: tuple[float, float, float, float],
    images: Sequence[tuple[str, npt.NDArray[np.float32]]],
    tile_w: int = 320,
) -> Image:
    """The frame with its box beside each likelihood image (red = target-like, blue = not)."""
    x, y, bw, bh = (round(v) for v in box)
    first = frame.copy()
    cv2.rectangle(first, (x, y), (x + bw, y + bh), (0, 255, 0), 2)
    tiles = [("frame", first)]
    for name, lik in images:
        norm = np.clip(lik / max(float(np.abs(lik).max()), 1e-6) * 127 + 128, 0, 255)
        heat = cv2.applyColorMap(norm.astype(np.uint8), cv2.COLORMAP_JET)
        cv2.rectangle(heat, (x, y), (x + bw, y + bh), (255, 255, 255), 1)
        tiles.append((name, heat))
    scale = tile_w / frame.shape[1]
    out = []
    for name, tile in tiles:
        small = cv2.resize(tile, (tile_w, max(1, round(frame.shape[0] * scale))))
        cv2.putText(small, name, (6, 18), _FONT, 0.5, (255, 255, 255), 2, cv2.LINE_AA)
        cv2.putText(small, name, (6, 18), _FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        out.append(small)
    return np.hstack(out)
