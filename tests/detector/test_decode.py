"""Letterbox geometry, head decoding and class-aware NMS on synthetic arrays."""

from __future__ import annotations

import numpy as np
import pytest

from tracker.detector_decode import (
    PAD_VALUE,
    class_aware_nms,
    decode,
    decode_head,
    letterbox,
    nms,
    sigmoid,
    to_image_boxes,
    to_input_boxes,
)

ANCHORS = np.array([[20.0, 30.0], [40.0, 40.0]], np.float32)


def _raw(num_classes: int, grid: int) -> np.ndarray:
    """All-negative logits (nothing detected) for 2 anchors."""
    return np.full((2 * (5 + num_classes), grid, grid), -12.0, np.float32)


def test_decode_head_places_box_from_cell_anchor_and_stride() -> None:
    """Zero offsets at anchor 1, cell (row 2, col 1), stride 16: centre (24, 40), anchor size."""
    raw = _raw(2, 4)
    base = 1 * 7  # anchor 1's channel block
    raw[base:base + 4, 2, 1] = 0.0  # tx = ty = tw = th = 0
    raw[base + 4, 2, 1] = 5.0  # objectness
    raw[base + 6, 2, 1] = 5.0  # class 1
    boxes, scores = decode_head(raw, ANCHORS, 16)
    best = int(np.argmax(scores.max(axis=1)))
    # cx = (2*0.5 - 0.5 + 1) * 16 = 24; cy = (2*0.5 - 0.5 + 2) * 16 = 40; w = h = 40
    np.testing.assert_allclose(boxes[best], [4.0, 20.0, 44.0, 60.0], atol=1e-4)
    assert scores[best].argmax() == 1
    assert scores[best, 1] == pytest.approx(float(sigmoid(np.array(5.0))) ** 2, rel=1e-5)


def test_decode_head_offsets_and_size_follow_logits() -> None:
    """Saturated tx/ty reach the +1.5/-0.5 cell limits; sigma(tw) = 0.75 gives 2.25 x anchor."""
    raw = _raw(1, 2)
    raw[0, 0, 0] = 20.0  # tx -> sigma = 1 -> cx = (2 - 0.5 + 0) * 8 = 12
    raw[1, 0, 0] = -20.0  # ty -> sigma = 0 -> cy = (-0.5) * 8 = -4
    raw[2, 0, 0] = np.log(3.0)  # sigma = 0.75 -> w = 2.25 * 20 = 45
    raw[3, 0, 0] = 0.0  # h = 30
    raw[4, 0, 0] = 8.0
    raw[5, 0, 0] = 8.0
    boxes, _ = decode_head(raw[:12], ANCHORS, 8)
    np.testing.assert_allclose(boxes[0], [12 - 22.5, -4 - 15, 12 + 22.5, -4 + 15], atol=1e-3)


def test_decode_keeps_only_scores_above_threshold_across_scales() -> None:
    """Two heads, one confident cell in the coarse head: exactly that box survives."""
    fine, coarse = _raw(3, 8), _raw(3, 4)
    coarse[4, 3, 3] = 6.0
    coarse[5 + 2, 3, 3] = 6.0
    coarse[0:4, 3, 3] = 0.0
    boxes, scores, classes = decode([fine, coarse], [ANCHORS, ANCHORS], [8, 16], 0.5)
    assert len(boxes) == 1
    assert classes.tolist() == [2]
    np.testing.assert_allclose(boxes[0], [56 - 10, 56 - 15, 56 + 10, 56 + 15], atol=1e-3)
    assert scores[0] > 0.99


def test_decode_head_rejects_bad_channel_count() -> None:
    with pytest.raises(ValueError, match="raw"):
        decode_head(np.zeros((11, 4, 4), np.float32), ANCHORS, 8)


def test_sigmoid_has_no_overflow_for_extreme_logits() -> None:
    with np.errstate(over="raise"):
        np.testing.assert_allclose(sigmoid(np.array([-1e4, 0.0, 1e4])), [0.0, 0.5, 1.0])


def test_nms_suppresses_overlaps_keeps_separate_boxes() -> None:
    boxes = np.array([[0, 0, 10, 10], [1, 1, 11, 11], [50, 50, 60, 60]], np.float64)
    scores = np.array([0.8, 0.9, 0.7])
    assert nms(boxes, scores, 0.5).tolist() == [1, 2]
    assert nms(boxes, scores, 0.99).tolist() == [1, 0, 2]


def test_class_aware_nms_never_suppresses_across_classes() -> None:
    """Same box as two categories: both kept; a duplicate of the same category: dropped."""
    boxes = np.array([[0, 0, 10, 10], [0, 0, 10, 10], [0.5, 0, 10.5, 10]], np.float64)
    scores = np.array([0.9, 0.6, 0.8])
    classes = np.array([0, 1, 0])
    assert class_aware_nms(boxes, scores, classes, 0.45, 10).tolist() == [0, 1]
    assert class_aware_nms(boxes, scores, classes, 0.45, 1).tolist() == [0]
    assert class_aware_nms(boxes[:0], scores[:0], classes[:0], 0.45, 10).tolist() == []


def test_letterbox_places_image_content_where_the_box_mapping_says() -> None:
    """A white rectangle in a 640x480 frame lands at the mapped box in the padded 416 input."""
    img = np.zeros((480, 640, 3), np.uint8)
    img[100:200, 300:420] = 255
    out, lb = letterbox(img, 416)
    assert out.shape == (416, 416, 3)
    assert lb.scale == pytest.approx(0.65)
    assert (lb.pad_x_px, lb.pad_y_px) == (0.0, 52.0)
    assert np.all(out[:52] == PAD_VALUE) and np.all(out[416 - 52:] == PAD_VALUE)
    x0, y0, x1, y1 = to_input_boxes(np.array([[300.0, 100.0, 420.0, 200.0]]), lb)[0]
    inside = out[int(y0) + 2:int(y1) - 2, int(x0) + 2:int(x1) - 2]
    assert inside.min() >= 250
    assert out[int(y0) - 3, int(x0):int(x1)].max() <= 5  # just above: black image, not pad


def test_letterbox_box_round_trip_and_clipping() -> None:
    rng = np.random.default_rng(3)
    for w, h in [(640, 480), (300, 900), (416, 416), (1280, 720)]:
        _, lb = letterbox(np.zeros((h, w, 3), np.uint8), 416)
        x0, y0 = rng.uniform(0, w / 2, 5), rng.uniform(0, h / 2, 5)
        boxes = np.stack([x0, y0, x0 + rng.uniform(1, w / 2, 5), y0 + rng.uniform(1, h / 2, 5)],
                         1)
        back = to_image_boxes(to_input_boxes(boxes, lb), lb, w, h)
        np.testing.assert_allclose(back, boxes, atol=1e-6)
    _, lb = letterbox(np.zeros((480, 640, 3), np.uint8), 416)
    clipped = to_image_boxes(np.array([[-20.0, 0.0, 500.0, 416.0]]), lb, 640, 480)
    np.testing.assert_allclose(clipped, [[0.0, 0.0, 640.0, 480.0]])
