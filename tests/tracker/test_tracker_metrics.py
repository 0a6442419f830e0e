"""Evaluation metrics (OTB conventions)."""

from __future__ import annotations

import numpy as np
import pytest

from companion.evaluation.metrics import ious, precision_curve, score, success_curve


def test_iou_of_known_boxes() -> None:
    a = np.array([[0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 10.0], [np.nan] * 4])
    b = np.array([[5.0, 0.0, 10.0, 10.0], [20.0, 20.0, 5.0, 5.0], [0.0, 0.0, 1.0, 1.0]])
    assert np.allclose(ious(a, b), [50 / 150, 0.0, 0.0])


def test_perfect_track_scores() -> None:
    truth = np.array([[10.0, 10.0, 20.0, 20.0]] * 5)
    s = score([tuple(r) for r in truth], truth)
    assert s.mean_centre_error_px == 0 and s.precision_20px == 1.0 and s.frames_lost == 0
    # IoU 1 exceeds every threshold but the last (1.0): 20 of 21
    assert s.success_auc == pytest.approx(20 / 21)


def test_lost_frames_count_as_misses_and_absent_truth_is_skipped() -> None:
    truth = np.array([[0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 10.0], [np.nan] * 4])
    pred = [(30.0, 0.0, 10.0, 10.0), None, None]
    s = score(pred, truth)
    assert s.frames == 2 and s.frames_lost == 1
    assert s.mean_centre_error_px == 30.0 and s.mean_error_x_px == 30.0
    assert s.mean_error_y_px == 0.0
    assert s.precision_20px == 0.0 and s.success_auc == 0.0


def test_curves_are_monotonic() -> None:
    rng = np.random.default_rng(0)
    iou = rng.random(50)
    err = rng.random(50) * 60
    assert np.all(np.diff(success_curve(iou)) <= 0)
    assert np.all(np.diff(precision_curve(err)) >= 0)
    assert precision_curve(err)[20] == pytest.approx(np.mean(err <= 20))


def test_length_mismatch_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="pred_boxes"):
        score([None], np.zeros((2, 4)))
