"""Generated textures (never downloaded): signpost plates, posters, facades, ground.

All functions are deterministic given the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import cv2
import numpy as np

from companion.core.frames import ImageU8

PX_PER_M = 128.0
MAX_SIDE_PX = 256
MIN_SIDE_PX = 24


def texture_size(width_m: float, height_m: float) -> tuple[int, int]:
    """(w, h) pixels for a face of the given size: ~PX_PER_M, longest side <= MAX_SIDE_PX."""
    scale = min(PX_PER_M, MAX_SIDE_PX / max(width_m, height_m))
    return (max(MIN_SIDE_PX, round(width_m * scale)), max(MIN_SIDE_PX, round(height_m * scale)))


def _hsv_colour(hue: float, sat: float, val: float) -> tuple[int, int, int]:
    px = np.array([[[hue % 180, sat, val]]], dtype=np.uint8)
    b, g, r = cv2.cvtColor(px, cv2.COLOR_HSV2BGR)[0, 0]
    return int(b), int(g), int(r)


def _logo(img: ImageU8, rng: np.random.Generator, colour: tuple[int, int, int]) -> None:
    """Draw one bold shape (circle, triangle, star, arrow or ring) in the upper part."""
    h, w = img.shape[:2]
    cx, cy, r = w // 2, int(h * 0.4), max(4, int(min(w, h) * 0.25))
    kind = int(rng.integers(0, 5))
    if kind == 0:
        cv2.circle(img, (cx, cy), r, colour, -1, cv2.LINE_AA)
    elif kind == 1:
        pts = np.array([[cx, cy - r], [cx - r, cy + r], [cx + r, cy + r]], np.int32)
        cv2.fillPoly(img, [pts], colour, cv2.LINE_AA)
    elif kind == 2:
        ang = np.arange(10) * np.pi / 5 - np.pi / 2
        rad = np.where(np.arange(10) % 2 == 0, r, r * 0.45)
        pts = np.stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)], 1).astype(np.int32)
        cv2.fillPoly(img, [pts], colour, cv2.LINE_AA)
    elif kind == 3:
        pts = np.array([[cx - r, cy - r // 3], [cx, cy - r // 3], [cx, cy - r], [cx + r, cy],
                        [cx, cy + r], [cx, cy + r // 3], [cx - r, cy + r // 3]], np.int32)
        cv2.fillPoly(img, [pts], colour, cv2.LINE_AA)
    else:
        cv2.circle(img, (cx, cy), r, colour, max(2, r // 3), cv2.LINE_AA)


def _text(img: ImageU8, text: str, colour: tuple[int, int, int]) -> None:
    h, w = img.shape[:2]
    label = text[:14] or "?"
    scale = 1.0
    (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, scale, 2)
    scale = min(0.9 * w / tw, 0.22 * h / th)
    (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, scale, 2)
    org = ((w - tw) // 2, int(h * 0.9))
    cv2.putText(img, label, org, cv2.FONT_HERSHEY_SIMPLEX, scale, colour, 2, cv2.LINE_AA)


def signpost_texture(
    rng: np.random.Generator, width_m: float, height_m: float, name: str
) -> ImageU8:
    """A saturated coloured plate with a white border, a logo and its name."""
    w, h = texture_size(width_m, height_m)
    hue = float(rng.uniform(0, 180))
    img = np.empty((h, w, 3), np.uint8)
    img[:] = _hsv_colour(hue, 220, 200)
    border = max(2, min(w, h) // 16)
    cv2.rectangle(img, (0, 0), (w - 1, h - 1), (245, 245, 245), border)
    _logo(img, rng, _hsv_colour(hue + 90, 200, 250))
    _text(img, name, (250, 250, 250))
    return img


def poster_texture(rng: np.random.Generator, width_m: float, height_m: float, name: str) -> ImageU8:
    """A poster: a two-colour gradient, a few shapes, a logo and its name."""
    w, h = texture_size(width_m, height_m)
    hue = float(rng.uniform(0, 180))
    c0 = np.array(_hsv_colour(hue, 200, 230), np.float32)
    c1 = np.array(_hsv_colour(hue + 25, 230, 120), np.float32)
    ramp = np.linspace(0.0, 1.0, h, dtype=np.float32)[:, None, None]
    img = np.ascontiguousarray(np.broadcast_to(c0 + ramp * (c1 - c0), (h, w, 3))).astype(np.uint8)
    for _ in range(3):
        p0 = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        p1 = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        cv2.rectangle(img, p0, p1, _hsv_colour(hue + 60, 120, 240), max(1, w // 40))
    _logo(img, rng, _hsv_colour(hue + 100, 230, 240))
    _text(img, name, (255, 255, 255))
    return img


def logo_texture(rng: np.random.Generator, width_m: float, height_m: float, name: str) -> ImageU8:
    """A facade logo: a round emblem (ring, disc, the name's initial) on a pale plate."""
    w, h = texture_size(width_m, height_m)
    hue = float(rng.uniform(0, 180))
    img = np.empty((h, w, 3), np.uint8)
    img[:] = _hsv_colour(hue + 90, 25, 235)
    centre, r = (w // 2, h // 2), max(6, int(min(w, h) * 0.46))
    cv2.circle(img, centre, r, _hsv_colour(hue, 220, 150), -1, cv2.LINE_AA)
    cv2.circle(img, centre, int(r * 0.78), _hsv_colour(hue + 20, 200, 235), -1, cv2.LINE_AA)
    letter = (name.strip()[:1] or "?").upper()
    scale = r / 22.0
    (tw, th), _ = cv2.getTextSize(letter, cv2.FONT_HERSHEY_DUPLEX, scale, max(1, r // 10))
    org = (centre[0] - tw // 2, centre[1] + th // 2)
    cv2.putText(img, letter, org, cv2.FONT_HERSHEY_DUPLEX, scale, _hsv_colour(hue, 230, 90),
                max(1, r // 10), cv2.LINE_AA)
    return img


def distractor_texture(
    rng: np.random.Generator, like: ImageU8, size_px: tuple[int, int]
) -> ImageU8:
    """A plate of the same mean colour as ``like`` with a different (striped) pattern."""
    w, h = size_px
    mean = like.reshape(-1, 3).mean(axis=0)
    img = np.empty((h, w, 3), np.uint8)
    img[:] = np.clip(mean, 0, 255).astype(np.uint8)
    step = max(3, w // int(rng.integers(4, 9)))
    darker = tuple(int(c) for c in np.clip(mean * 0.8, 0, 255))
    for x in range(0, w, 2 * step):
        cv2.rectangle(img, (x, 0), (x + step // 2, h - 1), darker, -1)
    return img


def facade_texture(rng: np.random.Generator, width_m: float, height_m: float) -> ImageU8:
    """A plain wall with rows of windows and a plinth band (~16 px per metre)."""
    ppm = 16.0
    w, h = max(16, round(width_m * ppm)), max(16, round(height_m * ppm))
    base = np.array(_hsv_colour(float(rng.uniform(5, 30)), 40, 190), np.float32)
    coarse = rng.normal(0.0, 6.0, (h // 4 + 1, w // 4 + 1)).astype(np.float32)
    noise = np.asarray(cv2.resize(coarse, (w, h), interpolation=cv2.INTER_LINEAR))[..., None]
    img = np.clip(base + noise, 0, 255).astype(np.uint8)
    win = (70, 60, 55)
    for y in np.arange(1.0, height_m - 1.0, 3.0):
        for x in np.arange(1.0, width_m - 1.0, 2.5):
            p0 = (int(x * ppm), int(y * ppm))
            cv2.rectangle(img, p0, (int((x + 1.2) * ppm), int((y + 1.5) * ppm)), win, -1)
    cv2.rectangle(img, (0, h - int(0.6 * ppm)), (w - 1, h - 1), (90, 95, 100), -1)
    return img


def ground_texture(rng: np.random.Generator, size_px: int) -> ImageU8:
    """Smooth grass/asphalt patches: low-frequency noise, so it does not alias when small."""
    coarse = rng.uniform(0.0, 1.0, (size_px // 32 + 1, size_px // 32 + 1)).astype(np.float32)
    field = cv2.resize(coarse, (size_px, size_px), interpolation=cv2.INTER_CUBIC)
    fine = rng.normal(0.0, 0.04, (size_px // 4, size_px // 4)).astype(np.float32)
    field = np.clip(field + cv2.resize(fine, (size_px, size_px)), 0.0, 1.0)[..., None]
    grass = np.array([60, 120, 80], np.float32)
    asphalt = np.array([105, 105, 110], np.float32)
    img = asphalt + (grass - asphalt) * field
    return np.clip(img, 0, 255).astype(np.uint8)


def sky_gradient(width: int, height: int) -> ImageU8:
    """Pale blue, lighter towards the bottom (copied behind every frame)."""
    top, bottom = np.array([200, 160, 120], np.float32), np.array([235, 220, 205], np.float32)
    ramp = np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None, None]
    img = top + ramp * (bottom - top)
    return np.ascontiguousarray(np.broadcast_to(img, (height, width, 3))).astype(np.uint8)
