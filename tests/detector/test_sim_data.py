"""The detector's simulated-world data: truth that matches the rendered frame."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.core.stream_format import TruthBox
from companion.sim import textures
from companion.sim.world import TEXTURES, Quad, SimLandmark, World, face_corners
from training import sim_pool
from training.sim_data import MIN_BOX_PX, SimScene, _hidden_share, sim_scene
from training.sim_pool import MIN_IN_VIEW, SCALE, pool_item
from training.synth_data import CATEGORIES


def test_a_scene_is_reproducible_from_its_seed() -> None:
    a, b = sim_scene(np.random.default_rng(7)), sim_scene(np.random.default_rng(7))
    assert np.array_equal(a.image_bgr, b.image_bgr)
    assert np.array_equal(a.boxes_xywh, b.boxes_xywh)
    assert np.array_equal(a.classes, b.classes)


@pytest.mark.parametrize("seed", range(12))
def test_boxes_lie_in_the_image_and_the_aimed_landmark_is_seen(seed: int) -> None:
    s = sim_scene(np.random.default_rng(seed), negative_rate=0.0)
    assert s.image_bgr.shape == (480, 640, 3)
    assert len(s.boxes_xywh) >= 1  # the camera always looks at one of the landmarks
    x, y, w, h = s.boxes_xywh.T
    assert np.all(x >= 0) and np.all(y >= 0) and np.all(w > 0) and np.all(h > 0)
    assert np.all(x + w <= 640) and np.all(y + h <= 480)
    assert set(s.classes.tolist()) <= set(range(len(CATEGORIES)))
    assert np.all((s.in_view > 0) & (s.in_view <= 1)) and np.all((s.hidden >= 0) & (s.hidden <= 1))


def test_negatives_have_no_landmark() -> None:
    for seed in range(5):
        s = sim_scene(np.random.default_rng(seed), 320, 240, negative_rate=1.0)
        assert len(s.boxes_xywh) == 0
        assert s.image_bgr.std() > 5.0  # a street was still rendered


def test_hidden_share_of_a_face_behind_another() -> None:
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    box = TruthBox("a", 0.0, 0.0, 10.0, 10.0, square)
    assert _hidden_share(box, [square]) == pytest.approx(1.0)
    assert _hidden_share(box, [square + np.array([5.0, 0.0])]) == pytest.approx(0.5)
    assert _hidden_share(box, [square + np.array([20.0, 0.0])]) == 0.0


def test_split_applies_the_thresholds_and_the_minimum_size() -> None:
    s = SimScene(np.zeros((4, 4, 3), np.uint8),
                 np.array([[0, 0, 20, 20], [0, 0, 20, 20], [0, 0, 20, 20], [0, 0, 3, 3]],
                          np.float32),
                 np.zeros(4, np.int64), np.array([1.0, 0.5, 1.0, 1.0]),
                 np.array([0.0, 0.0, 0.4, 0.0]))
    keep, rest = s.split(0.9, 0.1)
    assert keep.tolist() == [0] and rest.tolist() == [1, 2, 3]
    assert MIN_BOX_PX > 3


@pytest.mark.parametrize(("category", "facades"), [("logo", 1), ("wall_image", 1),
                                                   ("other", 0), ("signpost", 0)])
def test_logos_hang_on_a_facade_like_wall_images(category: str, facades: int) -> None:
    """A facade logo gets a wall behind it (and its own emblem texture); a bare plate not."""
    rng = np.random.default_rng(0)
    centre = np.array([0.0, 10.0, -4.0])
    make = TEXTURES.get(category, textures.poster_texture)
    tex = make(rng, 2.0, 2.0, "Zeta")
    quad = Quad(face_corners(centre, 2.0, 2.0, 270.0), tex, landmark_id="a")
    world = World([SimLandmark("a", "Zeta", category, centre, 2.0, 2.0, 270.0, quad)])
    assert len(world.facades) == facades
    if category == "logo":  # a pale plate around a saturated emblem
        hsv = cv2.cvtColor(tex, cv2.COLOR_BGR2HSV)
        assert hsv[2, 2, 1] < 60 and hsv[tex.shape[0] // 2, tex.shape[1] // 4, 1] > 120


def test_pool_targets_are_the_scene_boxes_at_the_letterbox_scale() -> None:
    seed, size = 5, 128
    side = round(size / SCALE)
    scene = sim_scene(np.random.default_rng(seed), side, side)
    image, rows = pool_item(seed, size)
    assert image.shape == (size, size, 3)
    keep, _ = scene.split(MIN_IN_VIEW, 0.5)
    b = scene.boxes_xywh[keep] * (size / side)
    assert np.allclose(rows[:, 0], scene.classes[keep])
    assert np.allclose(rows[:, 1:3], b[:, :2] + b[:, 2:] / 2, atol=1e-4)
    assert np.allclose(rows[:, 3:], b[:, 2:], atol=1e-4)


@pytest.mark.parametrize("count", ["0", "-3", "many"])
def test_a_bad_pool_size_is_one_line_and_exit_2(count: str, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "pool.npz"
    monkeypatch.setattr(sys, "argv", ["sim_pool.py", "--count", count, "--out", str(out)])
    with pytest.raises(SystemExit) as stop:
        sim_pool.main()
    assert stop.value.code == 2 and not out.exists()
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        f"sim_pool.py: error: argument --count: expected an integer >= 1, got "
        f"{count if count.lstrip('-').isdigit() else repr(count)}")
