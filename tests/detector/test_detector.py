"""The committed detector model: loading checks, detection on simulated frames, matching."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracker.detector import (
    DEFAULT_MODEL_PATH,
    Detection,
    Detector,
    DetectorConfig,
    DetectorError,
    match_detection,
)
from tracker.detector_decode import iou_one_to_many
from training.evaluation import SIM_SEED, EvalFrame, sim_frame
from training.synth_data import CATEGORIES

FIXTURES = Path(__file__).resolve().parent / "fixtures"


@pytest.fixture(scope="module")
def detector() -> Detector:
    return Detector()


def _xyxy(box: tuple[float, float, float, float] | np.ndarray) -> np.ndarray:
    x, y, w, h = box
    return np.array([x, y, x + w, y + h], np.float64)


def test_committed_model_loads_with_landmark_categories(detector: Detector) -> None:
    assert detector.model_path == DEFAULT_MODEL_PATH
    assert DEFAULT_MODEL_PATH.stat().st_size <= 10_000_000
    assert {"signpost", "wall_image"} <= set(detector.categories)
    assert detector.info.input_size == 416
    assert detector.info.strides == (8, 16, 32)  # the paper's added 52x52 head


def _big_landmark_frame(seed: int) -> EvalFrame:
    """The first held-out simulated frame from ``seed`` on with a counted face >= 48 px."""
    while True:
        frame = sim_frame(seed)
        if len(frame.boxes_xywh) and frame.boxes_xywh[:, 2:].max() >= 48:
            return frame
        seed += 1


@pytest.mark.parametrize("seed", [SIM_SEED + 11 * k for k in range(6)])
def test_detects_a_simulated_landmark_in_a_640x480_frame(detector: Detector, seed: int) -> None:
    """The largest counted landmark (>= 48 px) of a held-out frame is found with its
    category and IoU > 0.5."""
    frame = _big_landmark_frame(seed)
    i = int(np.argmax(frame.boxes_xywh[:, 2:].max(axis=1)))
    truth = _xyxy(frame.boxes_xywh[i])
    want = CATEGORIES[int(frame.classes[i])]
    dets = detector.detect(frame.image_bgr)
    same = [d for d in dets if d.category == want]
    assert same, f"no {want} detected; got {[(d.category, d.score) for d in dets]}"
    ious = iou_one_to_many(truth, np.array([_xyxy(d.box) for d in same]))
    assert ious.max() > 0.5
    assert all(0.0 < d.score <= 1.0 for d in dets)


def test_uniform_frame_gives_no_detection(detector: Detector) -> None:
    assert detector.detect(np.full((480, 640, 3), 128, np.uint8)) == []


def test_config_model_path_is_used_when_no_argument(tmp_path: Path) -> None:
    missing = tmp_path / "elsewhere.onnx"
    with pytest.raises(DetectorError, match=r"elsewhere\.onnx: model file not found"):
        Detector(config=DetectorConfig(model_path=str(missing)))


def _one_line_error(path: Path | str) -> str:
    with pytest.raises(DetectorError) as info:
        Detector(path)
    msg = str(info.value)
    assert isinstance(info.value, ValueError)
    assert "\n" not in msg
    assert str(path) in msg
    return msg


def test_missing_model_file(tmp_path: Path) -> None:
    assert "not found" in _one_line_error(tmp_path / "none.onnx")


def test_model_path_is_a_folder(tmp_path: Path) -> None:
    assert "not a file" in _one_line_error(tmp_path)


def test_corrupt_model_file(tmp_path: Path) -> None:
    bad = tmp_path / "corrupt.onnx"
    bad.write_bytes(DEFAULT_MODEL_PATH.read_bytes()[:5000][::-1])
    assert "not a valid ONNX model" in _one_line_error(bad)


def test_model_with_wrong_input_shape() -> None:
    msg = _one_line_error(FIXTURES / "wrong_input_shape.onnx")
    assert "wrong input shape [1, 1, 64, 50]" in msg


def test_model_with_unsupported_opset() -> None:
    msg = _one_line_error(FIXTURES / "opset_too_high.onnx")
    assert "unsupported ONNX opset 99" in msg


def test_rejects_non_bgr_image(detector: Detector) -> None:
    with pytest.raises(ValueError, match="image_bgr"):
        detector.detect(np.zeros((32, 32), np.uint8))
    with pytest.raises(ValueError, match="image_bgr"):
        detector.detect(np.zeros((32, 32, 3), np.float32))


def test_match_detection_prefers_category_then_nearest_inside_gate() -> None:
    dets = [Detection((100, 100, 20, 20), "signpost", 0.9),
            Detection((300, 300, 20, 20), "signpost", 0.6),
            Detection((305, 305, 20, 20), "wall_image", 0.95)]
    assert match_detection(dets, "signpost") is dets[0]  # no prior: best score
    assert match_detection(dets, "signpost", (310.0, 310.0), 50.0) is dets[1]
    assert match_detection(dets, "signpost", (600.0, 600.0), 50.0) is None
    assert match_detection(dets, "logo") is None
