"""Detector data from the simulated world (``companion.sim``): random streets, truth boxes.

Each scene is a random street built from the simulator's own parts: 1-5 landmarks
(signposts on poles, wall images and logos on a facade) with the textures the simulated
camera gives map landmarks without a reference image, the facades, poles and ground the
:class:`~companion.sim.world.World` builds around them, and the same image effects as the
scenarios (illumination, colour cast, shadow, occluder, motion blur, sensor noise) plus
same-coloured striped distractor plates. The camera looks at one landmark from a random
direction (up to 60 deg off its normal, -25..+45 deg elevation) at the distance that gives
it a chosen size, log-uniform 16..320 px with 40 % of the draws under 32 px, and aims a
little off it. A share of scenes are negatives: the same street with the landmarks' faces
replaced by distractors. Truth boxes come from :meth:`Renderer.truth_box` (the visible part
of the face, clipped to the image) with the share of the face in the image and the share
hidden behind nearer landmarks, so that training and evaluation choose which faces count
(:meth:`SimScene.split`).

Everything is seeded: ``sim_scene(np.random.default_rng(seed), ...)`` is reproducible.
"""

from __future__ import annotations

import string
from dataclasses import dataclass

import cv2
import numpy as np

from companion.core.stream_format import TruthBox
from companion.sim import textures
from companion.sim.effects import (
    EffectSpec,
    add_noise,
    apply_occlusion,
    apply_shadow,
    motion_blur,
    noise_bank,
)
from companion.sim.render import Renderer, polygon_area
from companion.sim.trajectory import KinematicState
from companion.sim.world import TEXTURES, Quad, SimLandmark, World, face_corners
from tracker.camera import CameraModel
from training.synth_data import CATEGORIES

SMALL_PX = 32.0  # a landmark is small when the larger side of its box is at most this
MIN_SIZE_PX, MAX_SIZE_PX, SMALL_SHARE = 16.0, 320.0, 0.4  # the chosen landmark's size
MIN_BOX_PX = 6.0  # faces smaller than this (larger side) never count
SIZES_M = {"signpost": ((0.5, 1.6), (0.4, 1.2)), "wall_image": ((1.2, 4.0), (1.0, 3.5)),
           "logo": ((0.8, 3.0), None)}


@dataclass(frozen=True)
class SimScene:
    """A rendered frame and every landmark face in it: boxes (x, y, w, h px, the visible
    part clipped to the image), class indices, the share of the face inside the image and
    the share hidden behind nearer landmarks."""

    image_bgr: np.ndarray
    boxes_xywh: np.ndarray
    classes: np.ndarray
    in_view: np.ndarray
    hidden: np.ndarray

    def split(self, min_in_view: float, max_hidden: float) -> tuple[np.ndarray, np.ndarray]:
        """Indices of the faces that count (in view and unhidden enough, >= MIN_BOX_PX)
        and of the rest."""
        big = self.boxes_xywh[:, 2:].max(axis=1, initial=0.0) >= MIN_BOX_PX
        ok = big & (self.in_view >= min_in_view) & (self.hidden <= max_hidden)
        return np.flatnonzero(ok), np.flatnonzero(~ok)


def _name(rng: np.random.Generator) -> str:
    letters = rng.choice(list(string.ascii_uppercase), int(rng.integers(3, 9)))
    return "".join(letters)


def _street(rng: np.random.Generator) -> list[SimLandmark]:
    """1-5 landmarks on a facade facing west at east = 0 (signposts stand in front)."""
    out: list[SimLandmark] = []
    north = float(rng.uniform(-12.0, -4.0))
    for i in range(int(rng.integers(1, 6))):
        category = CATEGORIES[int(rng.choice(3, p=(0.4, 0.35, 0.25)))]
        (w0, w1), hs = SIZES_M[category]
        width = float(np.exp(rng.uniform(np.log(w0), np.log(w1))))
        height = width if hs is None else float(rng.uniform(*hs)) * (
            1.0 if category == "signpost" else width / 2.0)
        if category == "signpost":
            east, down = -float(rng.uniform(0.8, 4.0)), -float(rng.uniform(1.8, 3.0)) - height / 2
            facing = 270.0 + float(rng.uniform(-35.0, 35.0))
        else:
            east, down = 0.0, -float(rng.uniform(1.0, 7.0)) - height / 2
            facing = 270.0
        north += width / 2.0
        centre = np.array([north, east, down])
        north += width / 2.0 + float(rng.uniform(0.5, 5.0))
        lid = f"lm{i}"
        tex = TEXTURES.get(category, textures.poster_texture)(rng, width, height, _name(rng))
        quad = Quad(face_corners(centre, width, height, facing), tex, landmark_id=lid)
        out.append(SimLandmark(lid, lid, category, centre, width, height, facing, quad))
    return out


def _look_at(position: np.ndarray, aim: np.ndarray, roll: float) -> KinematicState:
    """A vehicle at ``position`` whose forward camera (zero mount) looks at ``aim``."""
    d = aim - position
    yaw = float(np.arctan2(d[1], d[0]))
    pitch = float(np.arctan2(-d[2], np.hypot(d[0], d[1])))
    return KinematicState(0.0, tuple(position), (0.0, 0.0, 0.0), (roll, pitch, yaw))


def _viewpoint(rng: np.random.Generator, target: SimLandmark, fx: float) -> KinematicState:
    """A camera at the distance that shows ``target`` at a random size, aimed at a point
    up to 0.35 of that distance off it (within about 19 deg: in view at 640x480)."""
    small = rng.random() < SMALL_SHARE
    lo, hi = (MIN_SIZE_PX, SMALL_PX) if small else (SMALL_PX, MAX_SIZE_PX)
    size_px = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    distance = fx * max(target.width_m, target.height_m) / size_px
    az = np.radians(target.facing_deg or 270.0) + np.radians(rng.uniform(-60.0, 60.0))
    el = np.radians(rng.uniform(-25.0, 45.0))
    offset = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
    position = target.centre_ned + distance * offset
    position[2] = min(position[2], -0.4)  # above the ground
    spread = distance * 0.35
    aim = target.centre_ned + rng.uniform(-spread, spread, 3) * np.array([1.0, 1.0, 0.6])
    return _look_at(position, aim, float(np.radians(rng.normal(0.0, 6.0))))


def _distractors(rng: np.random.Generator, landmarks: list[SimLandmark]) -> list[Quad]:
    """Striped plates of a landmark's colour, and plain boards, beside the landmarks."""
    out = []
    for lm in landmarks:
        if rng.random() < 0.35:
            tex = lm.quad.texture
            assert tex is not None
            plate = textures.distractor_texture(rng, tex, (tex.shape[1], tex.shape[0]))
            shift = np.array([float(rng.choice([-1, 1])) * (lm.width_m + rng.uniform(0.5, 3)),
                              -0.01, float(rng.uniform(-1.0, 1.0))])
            out.append(Quad(lm.quad.corners_ned + shift, plate))
    return out


def _hidden_share(box: TruthBox, nearer: list[np.ndarray]) -> float:
    """Share of a face's image outline covered by nearer landmarks' outlines."""
    assert box.corners_px is not None
    face = box.corners_px.astype(np.float32)
    area = polygon_area(box.corners_px)
    covered = 0.0
    for other in nearer:
        inter, _ = cv2.intersectConvexConvex(face, other.astype(np.float32))
        covered += float(inter)
    return min(1.0, covered / area) if area > 0 else 1.0


def _effects(rng: np.random.Generator, image: np.ndarray, boxes: list[TruthBox],
             seed: int) -> np.ndarray:
    """Shadow / occluder on a landmark, illumination, colour cast, blur, noise."""
    for box in boxes:
        if rng.random() < 0.12:
            apply_shadow(image, box, EffectSpec("shadow", strength=float(rng.uniform(0.2, 0.6)),
                                                fraction_start=float(rng.uniform(0.2, 0.6)),
                                                angle_deg=float(rng.uniform(0, 360))), 0.0)
        elif rng.random() < 0.06:
            apply_occlusion(image, box, EffectSpec("occlusion",
                                                   fraction_start=float(rng.uniform(0.1, 0.3)),
                                                   angle_deg=float(rng.choice([0, 180, 270]))),
                            0.0)
    gain = float(np.exp(rng.uniform(np.log(0.45), np.log(1.7))))
    cast = rng.uniform(0.85, 1.15, 3) if rng.random() < 0.4 else np.ones(3)
    image = np.asarray(cv2.multiply(image, np.array([*(gain * cast), 0.0])), np.uint8)
    if rng.random() < 0.2:
        image = motion_blur(image, int(rng.integers(3, 12)), float(rng.uniform(0, 180)))
    sigma = float(rng.uniform(0.0, 6.0))
    if sigma > 0.5:
        image = add_noise(image, noise_bank(image.shape, sigma, seed), rng)
    return image


def sim_scene(rng: np.random.Generator, width: int = 640, height: int = 480,
              negative_rate: float = 0.12) -> SimScene:
    """One random simulated-world frame (``width`` x ``height``) with its truth."""
    fx = float(rng.uniform(420.0, 640.0))
    camera = CameraModel(width=width, height=height, fx=fx, fy=fx,
                         cx=(width - 1) / 2.0, cy=(height - 1) / 2.0)
    landmarks = _street(rng)
    world = World(landmarks, seed=int(rng.integers(0, 2**31)))
    state = _viewpoint(rng, landmarks[int(rng.integers(0, len(landmarks)))], fx)
    extra = _distractors(rng, landmarks)
    negative = rng.random() < negative_rate
    if negative:  # the same street, every landmark's face swapped for a look-alike
        for lm in landmarks:
            tex = lm.quad.texture
            assert tex is not None
            extra.append(Quad(lm.quad.corners_ned, textures.distractor_texture(
                rng, tex, (tex.shape[1], tex.shape[0]))))
        world.landmarks = []
    renderer = Renderer(camera, world)
    rendered = renderer.render(state, extra)
    pos, r = np.asarray(state.position_ned_m), rendered.camera.r_ned_cam
    faces = [(b, world.landmark(b.landmark_id).quad) for b in rendered.boxes]
    faces += [(b, q) for q in extra if (b := renderer.truth_box(q, r, pos))]
    rows, seen = [], []
    for box, quad in sorted(faces, key=lambda f: float(np.linalg.norm(f[1].centre_ned - pos))):
        assert box.corners_px is not None
        if quad.landmark_id:  # near to far: what is seen so far is in front
            hidden = _hidden_share(box, seen) if seen else 0.0
            category = CATEGORIES.index(world.landmark(box.landmark_id).category)
            rows.append((box.x, box.y, box.w, box.h, category, box.in_view_frac, hidden))
        seen.append(box.corners_px)
    a = np.array(rows, np.float64).reshape(-1, 7)
    image = _effects(rng, rendered.image, list(rendered.boxes), int(rng.integers(0, 2**31)))
    return SimScene(image, a[:, :4].astype(np.float32), a[:, 4].astype(np.int64), a[:, 5],
                    a[:, 6])
