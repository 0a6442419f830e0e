"""Effects scripted over time, each changing what it names and nothing else.

Order within a frame: distractors are drawn into the world by the renderer; then per
landmark shadow and occlusion (image space, on the landmark's projected face or box);
then global illumination (ramp, step) and colour cast; then motion blur; sensor noise
last.  Randomness comes from ``numpy.random.default_rng([seed, frame index, effect no])``
so a frame's look depends only on the seed and the frame, not on what ran before.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal

import cv2
import numpy as np

from companion.core.frames import ImageU8
from companion.core.stream_format import TruthBox
from companion.sim import textures
from companion.sim.render import clip_halfspace, clip_rect
from companion.sim.world import Quad, World, seeded_rng
from tracker.geometry import FloatArray

EffectKind = Literal[
    "illumination_ramp",
    "illumination_step",
    "colour_cast",
    "shadow",
    "occlusion",
    "noise",
    "motion_blur",
    "distractor",
    "vignette",
]
FOREVER_S = 1e9


@dataclass(frozen=True)
class EffectSpec:
    """One scripted effect, active from ``start_s`` to ``end_s`` (scenario seconds).

    * ``illumination_ramp``: gain goes from ``gain_start`` (before and at ``start_s``) to
      ``gain_end`` (at and after ``end_s``) linearly.
    * ``illumination_step``: gain ``gain_end`` inside the window, 1 outside.
    * ``colour_cast``: channels multiplied by ``cast_bgr`` inside the window.
    * ``shadow``: the part of landmark ``landmark_id``'s face beyond a line darkened by
      ``strength``; the shaded share goes from ``fraction_start`` to ``fraction_end``
      over the window; ``angle_deg`` is the direction the shadow comes from (0 = left,
      90 = top, 180 = right, 270 = bottom).
    * ``occlusion``: a ``colour_bgr`` occluder covers that share of the landmark's box,
      coming in from ``angle_deg`` like the shadow.
    * ``noise``: Gaussian sensor noise of ``sigma`` grey levels.
    * ``motion_blur``: a line blur ``length_px`` long at ``angle_deg``.
    * ``distractor``: a plate of the landmark's mean colour, same size and facing,
      ``offset_m`` (NED) away from it; drawn in the world, never in the truth.
    * ``vignette``: the lens darkens towards the corners: gain ``1 - strength r^2``, r the
      distance from the image centre over the half-diagonal (before the sensor noise).
    """

    kind: EffectKind = "noise"
    start_s: float = 0.0
    end_s: float = FOREVER_S
    landmark_id: str = ""
    gain_start: float = field(default=1.0, metadata={"ge": 0})
    gain_end: float = field(default=1.0, metadata={"ge": 0})
    cast_bgr: tuple[float, float, float] = (1.0, 1.0, 1.0)
    strength: float = field(default=0.5, metadata={"ge": 0, "le": 1})
    fraction_start: float = field(default=0.5, metadata={"ge": 0, "le": 1})
    fraction_end: float = field(default=0.5, metadata={"ge": 0, "le": 1})
    angle_deg: float = 0.0
    sigma: float = field(default=4.0, metadata={"ge": 0})
    length_px: int = field(default=9, metadata={"ge": 1})
    colour_bgr: tuple[int, int, int] = (70, 70, 75)
    offset_m: tuple[float, float, float] = (0.0, -4.0, 0.0)

    def active(self, t_s: float) -> bool:
        """True inside [start_s, end_s)."""
        return self.start_s <= t_s < self.end_s

    def progress(self, t_s: float) -> float:
        """0 at start_s, 1 at end_s (clamped)."""
        span = self.end_s - self.start_s
        return 1.0 if span <= 0 else min(1.0, max(0.0, (t_s - self.start_s) / span))

    def fraction(self, t_s: float) -> float:
        """The covered share at ``t_s`` (linear from fraction_start to fraction_end)."""
        return self.fraction_start + self.progress(t_s) * (self.fraction_end - self.fraction_start)


def gain_at(spec: EffectSpec, t_s: float) -> float:
    """Illumination gain of a ramp or step effect at ``t_s``."""
    if spec.kind == "illumination_ramp":
        return spec.gain_start + spec.progress(t_s) * (spec.gain_end - spec.gain_start)
    return spec.gain_end if spec.active(t_s) else 1.0


def _cover_polygon(poly: FloatArray, angle_deg: float, fraction: float) -> FloatArray:
    """Part of ``poly`` within ``fraction`` of its extent, measured from side ``angle_deg``.

    The direction d points from the covered side inwards (0 deg: from the left).
    """
    a = math.radians(angle_deg)
    d = np.array([math.cos(a), math.sin(a)])  # 0: +x (from left), 90: +y (from top)
    proj = poly @ d
    cut = proj.min() + fraction * (proj.max() - proj.min())
    return clip_halfspace(poly, -d, -cut)  # keep p.d <= cut


def _fill_mask(shape: tuple[int, int], poly: FloatArray) -> np.ndarray:
    mask = np.zeros(shape, np.uint8)
    if len(poly) >= 3:
        cv2.fillPoly(mask, [np.round(poly * 16).astype(np.int32)], 255, cv2.LINE_8, 4)
    return mask


def apply_shadow(image: ImageU8, box: TruthBox, spec: EffectSpec, t_s: float) -> None:
    """Darken the shaded part of the landmark's face in place."""
    if box.corners_px is None:
        return
    h, w = image.shape[:2]
    face = clip_rect(np.asarray(box.corners_px), 0.0, 0.0, w - 1.0, h - 1.0)
    if len(face) < 3:
        return
    part = _cover_polygon(face, spec.angle_deg, spec.fraction(t_s))
    mask = _fill_mask((h, w), part).astype(bool)
    image[mask] = (image[mask] * (1.0 - spec.strength)).astype(np.uint8)


def apply_occlusion(image: ImageU8, box: TruthBox, spec: EffectSpec, t_s: float) -> None:
    """Paint an occluder over the covered share of the landmark's box in place."""
    h, w = image.shape[:2]
    rect = np.array([[box.x, box.y], [box.x + box.w, box.y], [box.x + box.w, box.y + box.h],
                     [box.x, box.y + box.h]])
    part = _cover_polygon(rect, spec.angle_deg, spec.fraction(t_s))
    mask = _fill_mask((h, w), part).astype(bool)
    image[mask] = spec.colour_bgr


def motion_blur(image: ImageU8, length_px: int, angle_deg: float) -> ImageU8:
    """Convolve with a normalised line kernel of ``length_px`` at ``angle_deg``."""
    k = np.zeros((length_px, length_px), np.float32)
    c = (length_px - 1) / 2.0
    a = math.radians(angle_deg)
    dx, dy = math.cos(a) * c, math.sin(a) * c
    cv2.line(k, (round(c - dx), round(c - dy)), (round(c + dx), round(c + dy)), 1.0, 1)
    k /= max(float(k.sum()), 1.0)
    return np.asarray(cv2.filter2D(image, -1, k, borderType=cv2.BORDER_REPLICATE), np.uint8)


@lru_cache(maxsize=8)
def vignette_gain(shape: tuple[int, ...], strength: float) -> np.ndarray:
    """Per-pixel gain ``1 - strength r^2`` (float32, the image's shape), r = distance from
    the centre over the half-diagonal."""
    h, w = shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = ((xs - (w - 1) / 2) ** 2 + (ys - (h - 1) / 2) ** 2) / (((w - 1) ** 2 + (h - 1) ** 2) / 4)
    gain = (1.0 - strength * r2).astype(np.float32)
    out = np.repeat(gain[..., None], shape[2], axis=2) if len(shape) == 3 else gain
    out.setflags(write=False)
    return out


NOISE_PAD = 64


def noise_bank(shape: tuple[int, ...], sigma: float, seed: int) -> np.ndarray:
    """Gaussian noise (int16, grey levels) a little larger than a frame, drawn once."""
    rng = np.random.default_rng([seed, 0x5E5])
    h, w = shape[0] + NOISE_PAD, shape[1] + NOISE_PAD
    bank = rng.standard_normal((h, w, *shape[2:]), dtype=np.float32) * np.float32(sigma)
    return np.round(bank).astype(np.int16)


def add_noise(image: ImageU8, bank: np.ndarray, rng: np.random.Generator) -> ImageU8:
    """Add a window of the noise bank at a random offset, saturating at 0 and 255.

    Drawing the full field every frame costs ~10 ms; a random window of a fixed field
    gives per-frame noise with no visible pattern for a tracker at a fraction of that.
    """
    h, w = image.shape[:2]
    dy, dx = (int(v) for v in rng.integers(0, NOISE_PAD, 2))
    window = bank[dy : dy + h, dx : dx + w]
    return np.asarray(cv2.add(image, window, dtype=cv2.CV_8U), np.uint8)


def distractor_quads(world: World, specs: Sequence[EffectSpec], t_s: float) -> list[Quad]:
    """World quads of the distractors active at ``t_s`` (cached textures per effect)."""
    out = []
    for n, spec in enumerate(specs):
        if spec.kind != "distractor" or not spec.active(t_s):
            continue
        lm = world.landmark(spec.landmark_id)
        tex = lm.quad.texture
        assert tex is not None
        rng = seeded_rng(world.seed, f"distractor:{n}:{spec.landmark_id}")
        size = (int(tex.shape[1]), int(tex.shape[0]))
        plate = textures.distractor_texture(rng, tex, size)
        corners = lm.quad.corners_ned + np.asarray(spec.offset_m, dtype=np.float64)
        out.append(Quad(corners, plate))
    return out


class EffectStack:
    """Applies a scenario's effects to rendered frames."""

    def __init__(self, specs: Sequence[EffectSpec], world: World, seed: int) -> None:
        self.specs = tuple(specs)
        self.seed = seed
        for spec in self.specs:
            if spec.kind in ("shadow", "occlusion", "distractor"):
                world.landmark(spec.landmark_id)  # KeyError for an unknown landmark
        self._distractors: dict[tuple[int, ...], list[Quad]] = {}
        self.world = world
        self._banks: dict[tuple[int, tuple[int, ...]], np.ndarray] = {}

    def occluded_frac(self, landmark_id: str, t_s: float) -> float:
        """Share of a landmark's box covered by active occlusion effects (the largest)."""
        fractions = [s.fraction(t_s) for s in self.specs if s.kind == "occlusion"
                     and s.landmark_id == landmark_id and s.active(t_s)]
        return max(fractions, default=0.0)

    def world_quads(self, t_s: float) -> list[Quad]:
        """Distractor quads to draw at ``t_s``."""
        if not any(s.kind == "distractor" for s in self.specs):
            return []
        key = tuple(i for i, s in enumerate(self.specs) if s.kind == "distractor" and s.active(t_s))
        if key not in self._distractors:
            self._distractors[key] = distractor_quads(self.world, self.specs, t_s)
        return self._distractors[key]

    def apply(
        self, image: ImageU8, t_s: float, index: int, boxes: Sequence[TruthBox]
    ) -> ImageU8:
        """The frame with every active effect applied (``image`` may be modified)."""
        by_id = {b.landmark_id: b for b in boxes}
        for spec in self.specs:
            box = by_id.get(spec.landmark_id)
            if box is not None and spec.active(t_s):
                if spec.kind == "shadow":
                    apply_shadow(image, box, spec, t_s)
                elif spec.kind == "occlusion":
                    apply_occlusion(image, box, spec, t_s)
        gain = np.ones(3)
        for spec in self.specs:
            if spec.kind in ("illumination_ramp", "illumination_step"):
                gain *= gain_at(spec, t_s)
            elif spec.kind == "colour_cast" and spec.active(t_s):
                gain *= np.asarray(spec.cast_bgr)
        if np.any(gain != 1.0):
            scale = np.asarray([*gain.tolist(), 0.0], dtype=np.float64)
            image = np.asarray(cv2.multiply(image, scale), dtype=np.uint8)
        for spec in self.specs:
            if spec.kind == "vignette" and spec.active(t_s) and spec.strength > 0:
                image = np.asarray(cv2.multiply(image, vignette_gain(image.shape, spec.strength),
                                                dtype=cv2.CV_8U), np.uint8)
            if spec.kind == "motion_blur" and spec.active(t_s):
                image = motion_blur(image, spec.length_px, spec.angle_deg)
        for n, spec in enumerate(self.specs):
            if spec.kind == "noise" and spec.active(t_s) and spec.sigma > 0:
                key = (n, image.shape)
                if key not in self._banks:
                    self._banks[key] = noise_bank(image.shape, spec.sigma, self.seed + n)
                rng = np.random.default_rng([self.seed, index, n])
                image = add_noise(image, self._banks[key], rng)
        return image
