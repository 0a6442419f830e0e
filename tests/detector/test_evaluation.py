"""Detector scoring (training/evaluation.py): VOC AP, matching, ignored boxes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from training.evaluation import EvalFrame, average_precision, evaluate, sim_frame


@dataclass(frozen=True)
class Hit:
    box: tuple[float, float, float, float]
    category: str
    score: float


class Scripted:
    """A detector that answers from a script (frame id -> detections)."""

    def __init__(self, answers: list[list[Hit]]) -> None:
        self.answers = answers
        self.calls = 0

    def detect(self, image: np.ndarray) -> list[Hit]:
        out = self.answers[self.calls]
        self.calls += 1
        return out


def frame(boxes: list[tuple[float, float, float, float]], classes: list[int],
          ignore: list[tuple[float, float, float, float]] = ()) -> EvalFrame:  # type: ignore[assignment]
    return EvalFrame(np.zeros((8, 8, 3), np.uint8), np.array(boxes, float).reshape(-1, 4),
                     np.array(classes, np.int64), np.array(ignore, float).reshape(-1, 4))


def test_average_precision_of_a_perfect_and_of_a_mixed_ranking() -> None:
    assert average_precision(np.array([0.9, 0.8]), np.array([True, True]), 2) == 1.0
    # ranks: hit, miss, hit -> precision 1 at recall 0.5, 2/3 at recall 1
    ap = average_precision(np.array([0.9, 0.8, 0.7]), np.array([True, False, True]), 2)
    assert ap == pytest.approx(0.5 * 1.0 + 0.5 * 2 / 3)
    assert average_precision(np.array([0.9]), np.array([False]), 1) == 0.0


def test_perfect_detections_score_one_and_wrong_categories_zero() -> None:
    frames = [frame([(10, 10, 20, 20)], [0]), frame([(50, 50, 10, 10)], [1])]
    exact = Scripted([[Hit((10, 10, 20, 20), "signpost", 0.9)],
                      [Hit((50, 50, 10, 10), "wall_image", 0.8)]])
    m = evaluate(exact, frames, 0.3)  # type: ignore[arg-type]
    assert m["mAP50"] == 1.0 and m["recall"] == 1.0 and m["precision"] == 1.0
    assert m["recall_small"] == 1.0 and m["n_small"] == 2
    wrong = Scripted([[Hit((10, 10, 20, 20), "logo", 0.9)], []])
    m = evaluate(wrong, frames, 0.3)  # type: ignore[arg-type]
    assert m["AP50_signpost"] == 0.0 and m["recall"] == 0.0 and m["precision"] == 0.0


def test_a_detection_on_an_ignored_box_is_no_false_alarm() -> None:
    frames = [frame([(10, 10, 20, 20)], [0], [(100, 100, 140, 140)])]
    det = Scripted([[Hit((10, 10, 20, 20), "signpost", 0.5),
                     Hit((101, 101, 39, 39), "signpost", 0.9)]])
    m = evaluate(det, frames, 0.3)  # type: ignore[arg-type]
    assert m["precision"] == 1.0 and m["mAP50"] == 1.0


def test_a_loose_box_is_a_miss_below_iou_one_half() -> None:
    frames = [frame([(0, 0, 40, 40)], [0])]
    m = evaluate(Scripted([[Hit((20, 20, 40, 40), "signpost", 0.9)]]), frames, 0.3)  # type: ignore[arg-type]
    assert m["recall"] == 0.0  # IoU 400 / 2800


def test_held_out_frames_count_only_faces_fully_in_view() -> None:
    f = sim_frame(1_000_003)
    assert f.image_bgr.shape == (480, 640, 3)
    assert len(f.boxes_xywh) == len(f.classes)
    both = np.concatenate([f.boxes_xywh[:, :2], f.ignore_xyxy[:, :2]])
    assert np.all(both >= 0)
