"""Each effect changes what it should and nothing else."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from companion.sim.effects import EffectSpec, EffectStack
from companion.sim.render import Renderer
from companion.sim.trajectory import KinematicState
from companion.sim.world import World


@pytest.fixture
def scene(one_landmark_world: World, east_state: KinematicState, camera):  # type: ignore[no-untyped-def]
    out = Renderer(camera, one_landmark_world).render(east_state)
    return one_landmark_world, out


def apply(world: World, out, spec: EffectSpec, t_s: float, index: int = 0) -> np.ndarray:  # type: ignore[no-untyped-def]
    return EffectStack([spec], world, seed=5).apply(out.image.copy(), t_s, index, out.boxes)


def face_mask(shape: tuple[int, ...], corners: np.ndarray, grow_px: int = 1) -> np.ndarray:
    mask = np.zeros(shape[:2], np.uint8)
    cv2.fillPoly(mask, [np.round(corners * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    return cv2.dilate(mask, np.ones((2 * grow_px + 1,) * 2, np.uint8)).astype(bool)


def changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.any(a != b, axis=2)


def test_illumination_ramp_scales_everything_by_the_ramp(scene) -> None:
    world, out = scene
    spec = EffectSpec("illumination_ramp", 2.0, 4.0, gain_start=1.0, gain_end=0.5)
    assert np.array_equal(apply(world, out, spec, 1.0), out.image)
    mid = apply(world, out, spec, 3.0).astype(float)
    assert np.abs(mid - out.image * 0.75).max() <= 1.0
    after = apply(world, out, spec, 9.0).astype(float)
    assert np.abs(after - out.image * 0.5).max() <= 1.0


def test_illumination_step_only_inside_its_window(scene) -> None:
    world, out = scene
    spec = EffectSpec("illumination_step", 2.0, 4.0, gain_end=0.4)
    assert np.array_equal(apply(world, out, spec, 1.9), out.image)
    assert np.array_equal(apply(world, out, spec, 4.0), out.image)
    inside = apply(world, out, spec, 2.0).astype(float)
    assert np.abs(inside - out.image * 0.4).max() <= 1.0


def test_colour_cast_scales_each_channel(scene) -> None:
    world, out = scene
    spec = EffectSpec("colour_cast", cast_bgr=(0.5, 1.0, 1.2))
    got = apply(world, out, spec, 0.0).astype(float)
    want = np.clip(out.image * np.array([0.5, 1.0, 1.2]), 0, 255)
    assert np.abs(got - want).max() <= 1.0
    assert np.array_equal(got[..., 1], out.image[..., 1])


def test_shadow_darkens_part_of_the_landmark_only(scene) -> None:
    world, out = scene
    spec = EffectSpec("shadow", landmark_id="L1", strength=0.5, fraction_start=0.4,
                      fraction_end=0.4, angle_deg=0.0)
    got = apply(world, out, spec, 0.0)
    diff = changed(got, out.image)
    box = out.boxes[0]
    assert not np.any(diff & ~face_mask(got.shape, box.corners_px))
    assert np.all(got[diff] <= out.image[diff])
    assert np.abs(got[diff] - out.image[diff] * 0.5).max() <= 1.0
    face = face_mask(got.shape, box.corners_px, grow_px=0)
    share = diff[face].mean()
    assert 0.35 < share < 0.45
    cols = np.nonzero(diff)[1]
    assert cols.max() < box.x + 0.45 * box.w  # it comes from the left


def test_occlusion_covers_the_share_of_the_box_with_its_colour(scene) -> None:
    world, out = scene
    spec = EffectSpec("occlusion", 0.0, 10.0, landmark_id="L1", fraction_start=0.0,
                      fraction_end=1.0, angle_deg=90.0, colour_bgr=(1, 2, 3))
    got = apply(world, out, spec, 5.0)  # half way: half of the box from the top
    diff = changed(got, out.image)
    box = out.boxes[0]
    rows, cols = np.nonzero(diff)
    assert cols.min() >= box.x - 1 and cols.max() <= box.x + box.w + 1
    assert rows.min() >= box.y - 1 and abs(rows.max() - (box.y + box.h / 2)) <= 1
    assert np.all(got[diff] == (1, 2, 3))
    stack = EffectStack([spec], world, seed=5)
    assert stack.occluded_frac("L1", 5.0) == 0.5 and stack.occluded_frac("L1", 10.0) == 0.0


def test_noise_has_its_sigma_and_depends_only_on_seed_and_frame(scene) -> None:
    world, out = scene
    spec = EffectSpec("noise", sigma=4.0)
    a = apply(world, out, spec, 0.0, index=3).astype(float)
    interior = (out.image > 20) & (out.image < 235)
    d = (a - out.image)[interior]
    assert abs(d.mean()) < 0.2 and 3.6 < d.std() < 4.4
    assert np.array_equal(apply(world, out, spec, 0.0, index=3), a.astype(np.uint8))
    assert not np.array_equal(apply(world, out, spec, 0.0, index=4), a.astype(np.uint8))


def test_motion_blur_changes_only_pixels_near_horizontal_change(scene) -> None:
    world, out = scene
    spec = EffectSpec("motion_blur", length_px=9, angle_deg=0.0)
    got = apply(world, out, spec, 0.0)
    img = out.image.astype(int)
    # a pixel whose +-4 px horizontal neighbourhood is constant cannot change
    flat = np.ones(img.shape[:2], bool)
    for dx in range(1, 5):
        flat[:, dx:-dx] &= np.all(img[:, dx:-dx] == img[:, 2 * dx:], axis=2)
        flat[:, dx:-dx] &= np.all(img[:, dx:-dx] == img[:, : -2 * dx], axis=2)
    flat[:, :4] = flat[:, -4:] = False
    diff = changed(got, out.image)
    assert diff.sum() > 100
    assert not np.any(diff & flat)


def test_distractor_draws_a_similar_plate_and_leaves_truth_alone(
    one_landmark_world: World, east_state: KinematicState, camera
) -> None:
    spec = EffectSpec("distractor", landmark_id="L1", offset_m=(-4.0, 0.0, 0.0))
    stack = EffectStack([spec], one_landmark_world, seed=5)
    r = Renderer(camera, one_landmark_world)
    plain = r.render(east_state)
    quads = stack.world_quads(0.0)
    with_d = r.render(east_state, quads)
    assert with_d.boxes[0].corners_px.tolist() == plain.boxes[0].corners_px.tolist()
    assert len(with_d.boxes) == 1
    pose = r.camera_pose(east_state)
    pc = (quads[0].corners_ned - pose[0]) @ pose[1]
    diff = changed(with_d.image, plain.image)
    assert diff.sum() > 500
    assert not np.any(diff & ~face_mask(plain.image.shape, r.image_outline(pc)))
    lm_colour = one_landmark_world.landmarks[0].quad.texture.reshape(-1, 3).mean(0)
    assert np.abs(with_d.image[diff].mean(0) - lm_colour).max() < 40
    assert stack.world_quads(-1.0) == []  # not before its start


def test_effects_outside_their_window_change_nothing(scene) -> None:
    world, out = scene
    for kind in ("colour_cast", "shadow", "occlusion", "noise", "motion_blur"):
        spec = dataclasses.replace(EffectSpec(kind, 5.0, 6.0, landmark_id="L1"),
                                   cast_bgr=(0.5, 0.5, 0.5))
        assert np.array_equal(apply(world, out, spec, 4.0), out.image), kind


def test_unknown_landmark_is_refused(one_landmark_world: World) -> None:
    with pytest.raises(KeyError):
        EffectStack([EffectSpec("shadow", landmark_id="nope")], one_landmark_world, 0)
