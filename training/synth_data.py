"""Procedural landmark scenes with truth boxes, for training and evaluating the detector.

Planar textured quads (signposts: coloured plates with a glyph or text; wall images: framed
posters; logos: round emblems) are perspective-warped with ``cv2.warpPerspective`` onto
generated ground or facade backgrounds with clutter (windows, bricks, cars, plain boards,
foliage), then the whole frame gets an illumination change, blur and sensor noise.  Many
landmarks are small (<= 32 px).  About one frame in eight is a negative (no landmark).

Pure numpy/OpenCV and deterministic given a ``numpy.random.Generator``; no torch, so the tests
and the evaluation benchmark use it from the run-time environment.
"""

from __future__ import annotations

import string
from dataclasses import dataclass

import cv2
import numpy as np

CATEGORIES: tuple[str, ...] = ("signpost", "wall_image", "logo")

_TEXT_CHARS = string.ascii_uppercase + string.digits


@dataclass(frozen=True)
class Scene:
    """One generated frame: BGR image and truth boxes (x, y, w, h px, top-left) with classes."""

    image_bgr: np.ndarray
    boxes_xywh: np.ndarray  # (N, 4) float32
    classes: np.ndarray  # (N,) int64, index into CATEGORIES


def _noise_field(rng: np.random.Generator, h: int, w: int, cells: int) -> np.ndarray:
    """Smooth noise in [0, 1], shape (h, w): bilinear upsampling of a coarse random grid."""
    coarse = rng.random((cells, cells)).astype(np.float32)
    return cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC).clip(0.0, 1.0)


def _rand_colour(rng: np.random.Generator, sat_lo: int, sat_hi: int,
                val_lo: int = 60) -> tuple[int, int, int]:
    """A random BGR colour with saturation in [sat_lo, sat_hi] and value >= val_lo."""
    hsv = np.array([[[rng.integers(0, 180), rng.integers(sat_lo, sat_hi + 1),
                      rng.integers(val_lo, 256)]]], np.uint8)
    bgr = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0]
    return (int(bgr[0]), int(bgr[1]), int(bgr[2]))


def _background(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Ground, facade or mixed background with low-frequency texture."""
    base = np.array(_rand_colour(rng, 0, 90, 50), np.float32)
    tex = _noise_field(rng, h, w, int(rng.integers(3, 12)))[..., None]
    fine = rng.normal(0.0, rng.uniform(3, 14), (h, w, 1)).astype(np.float32)
    img = base * (0.6 + 0.8 * tex) + fine
    kind = rng.integers(0, 3)
    if kind == 1:  # facade: brick courses
        step = int(rng.integers(4, 14))
        img[::step, :, :] *= 0.7
        for y0 in range(0, h, step):
            off = (y0 // step % 2) * step
            img[y0:y0 + step, off::2 * step, :] *= 0.8
    elif kind == 2:  # horizon: sky band over ground
        sky = np.array(_rand_colour(rng, 0, 60, 150), np.float32)
        split = int(rng.uniform(0.2, 0.6) * h)
        grad = np.linspace(1.1, 0.9, split, dtype=np.float32)[:, None, None]
        img[:split] = sky * grad
    return img.clip(0, 255).astype(np.uint8)


def _clutter(rng: np.random.Generator, img: np.ndarray, count: int) -> None:
    """Draw distractors in place: windows, plain boards, cars, foliage, stripes, blobs."""
    h, w = img.shape[:2]
    for _ in range(count):
        kind = rng.integers(0, 6)
        s = int(np.exp(rng.uniform(np.log(6), np.log(max(8, min(h, w) // 3)))))
        x, y = int(rng.integers(-s // 2, w)), int(rng.integers(-s // 2, h))
        col = _rand_colour(rng, 0, 255 if kind in (1, 4) else 80, 20)
        if kind == 0:  # window: dark pane, light frame
            cv2.rectangle(img, (x, y), (x + s, y + int(s * 1.4)), col, max(1, s // 10))
            cv2.rectangle(img, (x + 2, y + 2), (x + s - 2, y + int(s * 1.4) - 2),
                          (40, 40, 40), -1)
        elif kind == 1:  # plain coloured board, no glyph
            cv2.rectangle(img, (x, y), (x + int(s * rng.uniform(0.5, 2)), y + s), col, -1)
        elif kind == 2:  # car-like rounded box
            cv2.rectangle(img, (x, y), (x + 2 * s, y + s), col, -1)
            cv2.circle(img, (x + s // 2, y + s), max(1, s // 4), (20, 20, 20), -1)
            cv2.circle(img, (x + 3 * s // 2, y + s), max(1, s // 4), (20, 20, 20), -1)
        elif kind == 3:  # foliage
            for _ in range(6):
                cv2.circle(img, (x + int(rng.integers(0, s + 1)), y + int(rng.integers(0, s + 1))),
                           max(1, s // 3), (int(rng.integers(10, 60)),
                                            int(rng.integers(60, 140)), int(rng.integers(10, 60))),
                           -1)
        elif kind == 4:  # plain filled circle
            cv2.circle(img, (x, y), max(1, s // 2), col, -1)
        else:  # road marking / stripe
            cv2.line(img, (x, y), (x + int(rng.integers(-2 * s, 2 * s + 1)), y + s), col,
                     max(1, s // 6))


def _words(rng: np.random.Generator, lo: int, hi: int) -> str:
    """A random 'word' of ``lo``..``hi`` capitals and digits."""
    return "".join(rng.choice(list(_TEXT_CHARS), size=int(rng.integers(lo, hi + 1))))


def _glyph(rng: np.random.Generator, img: np.ndarray, cx: int, cy: int, r: int,
           ink: tuple[int, int, int]) -> None:
    """Draw an arrow, triangle, disc or star of radius ``r`` at (cx, cy) in place."""
    kind = rng.integers(0, 4)
    if kind == 0:
        pts = np.array([[-1, -0.2], [0.25, -0.2], [0.25, -0.6], [1, 0], [0.25, 0.6],
                        [0.25, 0.2], [-1, 0.2]]) * r
        if rng.random() < 0.5:
            pts[:, 0] = -pts[:, 0]
    elif kind == 1:
        pts = np.array([[0, -1], [0.9, 0.7], [-0.9, 0.7]]) * r
    elif kind == 2:
        cv2.circle(img, (cx, cy), r, ink, -1)
        return
    else:
        ang = np.pi / 2 + np.arange(10) * np.pi / 5
        rad = np.where(np.arange(10) % 2 == 0, 1.0, 0.45) * r
        pts = np.stack([rad * np.cos(ang), -rad * np.sin(ang)], 1)
    cv2.fillPoly(img, [(pts + np.array([cx, cy])).astype(np.int32)], ink)


def _signpost_texture(rng: np.random.Generator) -> np.ndarray:
    """A saturated plate (aspect 1..2.8): big text, a glyph, or a glyph over a caption."""
    pw, ph = int(rng.integers(64, 180)), 64
    plate = np.full((ph, pw, 3), _rand_colour(rng, 170, 255, 120), np.uint8)
    ink = (255, 255, 255) if rng.random() < 0.75 else (20, 20, 20)
    if rng.random() < 0.6:
        cv2.rectangle(plate, (3, 3), (pw - 4, ph - 4), ink, 3)
    layout = rng.integers(0, 3)
    if layout == 0:
        text = _words(rng, 1, max(1, pw // 45))
        cv2.putText(plate, text, (10, 46), cv2.FONT_HERSHEY_SIMPLEX, 1.3, ink, 4)
    elif layout == 1:
        _glyph(rng, plate, pw // 2, ph // 2, 24, ink)
    else:
        _glyph(rng, plate, pw // 2, 24, 15, _rand_colour(rng, 120, 255, 120))
        cv2.putText(plate, _words(rng, 2, max(2, pw // 14)), (6, 56),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.45, ink, 1)
    return plate


def _poster_texture(rng: np.random.Generator) -> np.ndarray:
    """A picture: colourful gradient with shapes, maybe a caption and a white or dark margin."""
    ph = int(rng.integers(90, 140))
    pw = int(ph * rng.uniform(0.65, 1.6))
    c1 = np.array(_rand_colour(rng, 100, 255, 80), np.float32)
    c2 = np.array(_rand_colour(rng, 100, 255, 80), np.float32)
    t = np.linspace(0.0, 1.0, ph, dtype=np.float32)[:, None, None]
    pic = (c1 * (1 - t) + c2 * t) * np.ones((1, pw, 1), np.float32)
    pic = pic.clip(0, 255).astype(np.uint8)
    for _ in range(int(rng.integers(2, 6))):
        col = _rand_colour(rng, 120, 255, 60)
        cx, cy = int(rng.integers(0, pw)), int(rng.integers(0, ph))
        r = int(rng.integers(6, max(7, ph // 3)))
        kind = rng.integers(0, 4)
        if kind == 0:
            cv2.circle(pic, (cx, cy), r, col, -1)
        elif kind == 1:
            cv2.rectangle(pic, (cx - r, cy - r), (cx + r, cy + r // 2), col, -1)
        elif kind == 2:
            cv2.rectangle(pic, (cx - r, cy - r // 2), (cx + 2 * r, cy + r // 2), col, 3)
        else:
            _glyph(rng, pic, cx, cy, r, col)
    if rng.random() < 0.5:
        cv2.putText(pic, _words(rng, 3, max(3, pw // 16)), (6, ph - 10),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 2)
    if rng.random() < 0.5:
        return pic
    margin = max(4, ph // 12)
    frame_col = (245, 245, 245) if rng.random() < 0.7 else (25, 25, 25)
    return cv2.copyMakeBorder(pic, margin, margin, margin, margin, cv2.BORDER_CONSTANT,
                              value=frame_col)


def _logo_texture(rng: np.random.Generator) -> np.ndarray:
    """A round emblem: coloured disc, ring, and an initial or star at the centre (RGBA)."""
    n = 128
    logo = np.zeros((n, n, 4), np.uint8)
    col = _rand_colour(rng, 160, 255, 100)
    ring = _rand_colour(rng, 0, 255, 180)
    cv2.circle(logo, (n // 2, n // 2), n // 2 - 1, (*ring, 255), -1)
    cv2.circle(logo, (n // 2, n // 2), n // 2 - 12, (*col, 255), -1)
    letter = str(rng.choice(list(string.ascii_uppercase)))
    cv2.putText(logo, letter, (n // 2 - 24, n // 2 + 22), cv2.FONT_HERSHEY_DUPLEX, 2.0,
                (*ring, 255), 5)
    return logo


def _quad_corners(rng: np.random.Generator, tw: int, th: int, size_px: float,
                  centre: tuple[float, float]) -> np.ndarray:
    """Image corners of a planar rectangle seen in perspective (yaw/pitch/roll of the plane)."""
    yaw, pitch = np.radians(rng.uniform(-55, 55)), np.radians(rng.uniform(-35, 35))
    roll = np.radians(rng.normal(0, 6))
    aspect = tw / th
    hw, hh = (0.5, 0.5 / aspect) if aspect >= 1 else (0.5 * aspect, 0.5)
    obj = np.array([[-hw, -hh, 0], [hw, -hh, 0], [hw, hh, 0], [-hw, hh, 0]], np.float64)
    rvec = np.array([pitch, yaw, roll], np.float64)
    f, dist = 3.0, 3.0  # focal length / distance in plate widths: mild perspective
    pts, _ = cv2.projectPoints(obj, rvec, np.array([0, 0, dist], np.float64),
                               np.array([[f, 0, 0], [0, f, 0], [0, 0, 1]], np.float64), None)
    pts = pts.reshape(4, 2)
    span = float(max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1])))
    return (pts - pts.mean(axis=0)) * (size_px / span) + np.asarray(centre)


def _paste(img: np.ndarray, tex: np.ndarray, corners: np.ndarray) -> None:
    """Warp ``tex`` (BGR or BGRA) onto ``img`` in place at the quad ``corners``."""
    th, tw = tex.shape[:2]
    src = np.array([[0, 0], [tw - 1, 0], [tw - 1, th - 1], [0, th - 1]], np.float32)
    m = cv2.getPerspectiveTransform(src, corners.astype(np.float32))
    h, w = img.shape[:2]
    colour = cv2.warpPerspective(np.ascontiguousarray(tex[..., :3]), m, (w, h),
                                 flags=cv2.INTER_AREA if tw > 64 else cv2.INTER_LINEAR)
    alpha_src = tex[..., 3] if tex.shape[2] == 4 else np.full((th, tw), 255, np.uint8)
    alpha = cv2.warpPerspective(alpha_src, m, (w, h), flags=cv2.INTER_LINEAR)
    a = (alpha.astype(np.float32) / 255.0)[..., None]
    img[:] = (img * (1 - a) + colour * a).astype(np.uint8)


def _photometric(rng: np.random.Generator, img: np.ndarray) -> np.ndarray:
    """Illumination change (gain, offset, gamma, colour cast, shading), blur and noise."""
    f = img.astype(np.float32) / 255.0
    f = f ** rng.uniform(0.6, 1.6)
    f = f * rng.uniform(0.55, 1.35) * rng.uniform(0.85, 1.15, 3) + rng.uniform(-0.08, 0.08)
    h, w = img.shape[:2]
    f *= (0.7 + 0.6 * _noise_field(rng, h, w, 3))[..., None]  # uneven lighting / shadows
    out = (f * 255.0).clip(0, 255)
    if rng.random() < 0.4:
        k = int(rng.choice([3, 5]))
        out = cv2.GaussianBlur(out, (k, k), 0)
    out = out + rng.normal(0, rng.uniform(1, 9), out.shape)
    return out.clip(0, 255).astype(np.uint8)


def _iou_xywh(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two (x, y, w, h) boxes."""
    ix = max(0.0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    inter = ix * iy
    return float(inter / (a[2] * a[3] + b[2] * b[3] - inter + 1e-9))


def render_scene(rng: np.random.Generator, width: int = 416, height: int = 416,
                 max_size_px: float = 180.0, negative_rate: float = 0.12,
                 max_landmarks: int = 5) -> Scene:
    """Generate one frame with 0..``max_landmarks`` landmarks and truth boxes.

    Landmark size (larger side of the box) is log-uniform in [10, ``max_size_px``] px with
    half of the draws pulled to [10, 32] px, so small landmarks are common.
    """
    img = _background(rng, height, width)
    _clutter(rng, img, int(rng.integers(2, 14)))
    boxes: list[np.ndarray] = []
    classes: list[int] = []
    n = 0 if rng.random() < negative_rate else int(rng.integers(1, max_landmarks + 1))
    for _ in range(n):
        cls = int(rng.integers(0, len(CATEGORIES)))
        tex = (_signpost_texture, _poster_texture, _logo_texture)[cls](rng)
        hi = 32.0 if rng.random() < 0.5 else max_size_px
        size = float(np.exp(rng.uniform(np.log(10.0), np.log(hi))))
        for _attempt in range(10):
            centre = (rng.uniform(size * 0.3, width - size * 0.3),
                      rng.uniform(size * 0.3, height - size * 0.3))
            corners = _quad_corners(rng, tex.shape[1], tex.shape[0], size, centre)
            x0, y0 = np.clip(corners.min(axis=0), 0, [width, height])
            x1, y1 = np.clip(corners.max(axis=0), 0, [width, height])
            box = np.array([x0, y0, x1 - x0, y1 - y0], np.float32)
            if box[2] < 6 or box[3] < 6:
                continue
            if all(_iou_xywh(box, b) < 0.05 for b in boxes):
                if cls == 0 and rng.random() < 0.5:  # a pole under the plate
                    foot = corners[2:].mean(axis=0)
                    cv2.line(img, (int(foot[0]), int(foot[1])),
                             (int(foot[0]), int(foot[1] + size * rng.uniform(1, 3))),
                             (110, 110, 110), max(1, int(size / 12)))
                _paste(img, tex, corners)
                boxes.append(box)
                classes.append(cls)
                break
    img = _photometric(rng, img)
    return Scene(img, np.array(boxes, np.float32).reshape(-1, 4),
                 np.array(classes, np.int64))
