"""Template refinement, the scale and aspect filters, and their use by the adaptive tracker."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from tracker import AdaptiveTracker
from tracker.config import RefineConfig
from tracker.refine import Refiner
from tracker.scale_filter import ScaleFilter, factor_pairs, grey_region, sample_size, samples
from tracker.template import as_float, crop, match

Frames = list[npt.NDArray[np.uint8]]


def _texture(h: int, w: int, seed: int) -> npt.NDArray[np.float32]:
    """Smooth random colour texture: blobs at several sizes."""
    rng = np.random.default_rng(seed)
    out = np.zeros((h, w, 3), np.float32)
    for cells, amp in ((6, 70.0), (18, 40.0), (48, 20.0)):
        small = rng.uniform(-amp, amp, size=(cells, cells * w // h + 1, 3)).astype(np.float32)
        out += cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    return np.clip(out + 128.0, 0, 255)


def _zoom_scene(frames: int, grow: float, stretch: float, seed: int = 1) -> tuple[Frames, list]:
    """A textured card over a textured background; its width grows by ``grow * stretch`` and
    its height by ``grow / stretch`` over the sequence while it drifts right.  Exact boxes."""
    bg = _texture(240, 320, seed)
    card = _texture(120, 160, seed + 7)
    card[:8], card[-8:], card[:, :8], card[:, -8:] = 30, 30, 30, 30  # dark frame
    images, boxes = [], []
    for i in range(frames):
        t = i / max(frames - 1, 1)
        w = 48.0 * grow**t * stretch**t
        h = 36.0 * grow**t / stretch**t
        cx, cy = 120.0 + 40.0 * t, 120.0 + 5.0 * np.sin(3 * t)
        m = np.array([[w / 160, 0, cx - w / 2], [0, h / 120, cy - h / 2]], np.float32)
        img = bg.copy()
        warped = cv2.warpAffine(card, m, (320, 240), flags=cv2.INTER_AREA)
        mask = cv2.warpAffine(np.ones((120, 160), np.float32), m, (320, 240)) > 0.5
        img[mask] = warped[mask]
        noise = np.random.default_rng(seed * 1000 + i).normal(0, 2.0, img.shape)
        images.append(np.clip(img + noise, 0, 255).astype(np.uint8))
        boxes.append((cx - w / 2, cy - h / 2, w, h))
    return images, boxes


def test_template_match_finds_a_subpixel_shift() -> None:
    image = as_float(_texture(80, 80, 3).astype(np.uint8), grey=False)
    box = np.array([30.0, 24.0])
    template = crop(image, np.array([40.0, 40.0]), box, (30, 24))
    found = match(image, template, np.array([42.7, 38.6]), box, 0.3, ((1.0, 1.0),))
    assert found.score > 0.95
    assert np.allclose(found.centre, [40.0, 40.0], atol=0.3)


def test_scale_filter_reads_the_size_change() -> None:
    """Trained on a box, it reports a box k steps too large as k steps to shrink."""
    images, boxes = _zoom_scene(1, grow=1.0, stretch=1.0)
    frame, (x, y, w, h) = images[0], boxes[0]
    centre, box = np.array([x + w / 2, y + h / 2]), np.array([w, h])
    factors = factor_pairs(17, 1.02, "scale")
    size = sample_size(box)
    region = grey_region(frame, centre, box)  # +- a whole box: covers every size sampled
    model = ScaleFilter.train(samples(region, centre, box, factors, size))
    found = [
        model.peak(model.spectrum(samples(region, centre, box * 1.02**k, factors, size)))
        for k in (-3, 0, 3)
    ]
    assert found == [3, 0, -3]


def test_factor_pairs() -> None:
    aspect = factor_pairs(9, 1.02, "aspect")
    assert np.allclose(aspect[:, 0] * aspect[:, 1], 1.0)
    assert aspect[4].tolist() == [1.0, 1.0]
    assert np.all(factor_pairs(5, 1.02, "width")[:, 1] == 1.0)
    assert np.all(factor_pairs(5, 1.02, "height")[:, 0] == 1.0)
    with pytest.raises(ValueError, match="kind"):
        factor_pairs(5, 1.02, "depth")


def _iou(a: tuple, b: tuple) -> float:
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[0] + a[2], b[0] + b[2]), min(a[1] + a[3], b[1] + b[3])
    inter = max(0.0, x1 - x0) * max(0.0, y1 - y0)
    return inter / (a[2] * a[3] + b[2] * b[3] - inter)


@pytest.mark.parametrize("grey", [False, True])
def test_box_follows_a_growing_target_in_colour_and_grey(grey: bool) -> None:
    """The card grows 1.6x in 60 frames; the box must follow it (overlap, not only centre)."""
    images, boxes = _zoom_scene(60, grow=1.6, stretch=1.0)
    if grey:
        images = [np.repeat(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY)[:, :, None], 3, 2) for f in images]
    t = AdaptiveTracker(seed=0)
    t.init(images[0], boxes[0])
    results = [t.update(f) for f in images[1:]]
    assert t.cue == ("grayscale" if grey else "colour")
    assert all(r.box is not None for r in results)
    last = results[-1].box
    assert last is not None
    assert last[2] / boxes[-1][2] == pytest.approx(1.0, abs=0.08)
    assert min(_iou(r.box, b) for r, b in zip(results[-10:], boxes[-10:], strict=True)) > 0.8


def test_box_follows_a_change_of_aspect() -> None:
    """Width x 1.25, height / 1.25 over 60 frames (the boat seen from a turning drone)."""
    images, boxes = _zoom_scene(60, grow=1.0, stretch=1.25)
    t = AdaptiveTracker(seed=0)
    t.init(images[0], boxes[0])
    results = [t.update(f) for f in images[1:]]
    last = results[-1].box
    assert last is not None
    aspect, truth = last[2] / last[3], boxes[-1][2] / boxes[-1][3]
    assert aspect / truth == pytest.approx(1.0, abs=0.08)  # it started 1.56x off the end's


def _two_copies(gap_px: int) -> tuple[npt.NDArray[np.uint8], np.ndarray, np.ndarray]:
    """A background with one textured card pasted twice, side by side ``gap_px`` apart; the
    cards' centres (x, y)."""
    image = _texture(120, 200, 5).astype(np.uint8)
    card = _texture(24, 30, 11).astype(np.uint8)
    left = np.array([60.0, 60.0])
    right = left + np.array([30.0 + gap_px, 0.0])
    for c in (left, right):
        x0, y0 = int(c[0]) - 15, int(c[1]) - 12
        image[y0 : y0 + 24, x0 : x0 + 30] = card
    return image, left, right


def _refiner(image: npt.NDArray[np.uint8], centre: np.ndarray, **changes: float) -> Refiner:
    config = dataclasses.replace(RefineConfig(), template_search_frac=1.2, **changes)
    box = np.array([30.0, 24.0])
    return Refiner(config, as_float(image, grey=False), centre, box, image, centre, box)


def test_match_reports_a_look_alike_as_a_rival() -> None:
    image, left, right = _two_copies(4)
    patch = as_float(image, grey=False)
    box = np.array([30.0, 24.0])
    template = crop(patch, left, box, (30, 24))
    found = match(patch, template, left, box, 1.2, ((1.0, 1.0),))
    assert found.score > 0.95 and found.rival > 0.95
    assert found.rival_centre is not None
    both = sorted([found.centre[0], found.rival_centre[0]])
    assert np.allclose(both, [left[0], right[0]], atol=1.0)
    alone = match(patch, template, left, box, 0.3, ((1.0, 1.0),))  # the copy out of reach
    assert alone.rival < alone.score - 0.3


def test_ambiguous_match_takes_the_copy_nearer_the_last_estimate() -> None:
    """Two equal peaks: the one nearer the last estimate wins (OpenCV's first maximum, the
    left copy, without the rule), and the frame is marked ambiguous for learning."""
    image, left, right = _two_copies(4)
    refiner = _refiner(image, left)
    patch = as_float(image, grey=False)
    found = refiner.locate(
        patch,
        np.stack([left + np.array([10.0, 0.0]), right + np.array([2.0, 0.0])]),
        np.array([30.0, 24.0]),
    )
    assert np.allclose(found.centre, right, atol=1.0)
    assert refiner.rival > found.score - refiner.config.template_rival_margin


def test_fast_template_and_size_filters_learn_only_reliable_frames() -> None:
    """The fast template skips an ambiguous or jumping frame; the slow template and the size
    filters skip a frame the slow template does not match (a shadow the fast one followed)."""
    image, left, _ = _two_copies(40)
    patch = as_float(image, grey=False)
    box = np.array([30.0, 24.0])
    other = left + np.array([3.0, 2.0])
    cases = {  # (rival, jumped, slow score) -> (fast learns, size filters learn)
        (-1.0, False, 0.9): (True, True),
        (0.85, False, 0.9): (False, True),
        (-1.0, True, 0.9): (False, True),
        (-1.0, False, 0.3): (True, False),
    }
    for (rival, jumped, slow), (fast_learns, size_learns) in cases.items():
        refiner = _refiner(image, left)
        refiner.rival, refiner.jumped, refiner.slow_score = rival, jumped, slow
        fast, num = refiner.template().copy(), refiner._sizers[0].model.num.copy()
        refiner.learn(patch, (other, box), image, (other, box), 0.9)
        assert (not np.allclose(refiner.template(), fast)) == fast_learns, (rival, jumped, slow)
        assert (not np.allclose(refiner._sizers[0].model.num, num)) == size_learns
