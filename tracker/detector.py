"""Landmark detector: a YOLOv3-tiny-style ONNX model run with onnxruntime (no torch).

The source paper (sec. 2.4) uses semantic detection to give each landmark its category and a
box, so that trackers start, and restart after a loss, on the right thing.  ``Detector`` loads
the model once (checking it, with a one-line ``DetectorError`` naming the file and the
problem), then ``detect(image_bgr)`` letterboxes the frame, runs the network, decodes the two
or three heads and applies class-aware NMS.

The model carries its own decoding metadata (ONNX ``metadata_props``): ``names`` (category per
class index), ``strides`` and ``anchors`` (per head, input pixels), written by
``training/train.py``.  The committed model is ``tracker/models/landmark_yolo_tiny3.onnx``
(see docs/detector.md).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tracker.detector_decode import (
    Letterbox,
    class_aware_nms,
    decode,
    letterbox,
    to_image_boxes,
)

DEFAULT_MODEL_PATH = Path(__file__).resolve().parent / "models" / "landmark_yolo_tiny3.onnx"


class DetectorError(ValueError):
    """A model file that cannot be used: one line naming the file and the problem."""


@dataclass(frozen=True)
class DetectorConfig:
    """Detector settings (config section ``[detector]``).

    ``model_path`` "" means the committed model.
    """

    model_path: str = ""
    score_threshold: float = field(default=0.3, metadata={"gt": 0.0, "lt": 1.0})
    nms_iou: float = field(default=0.45, metadata={"gt": 0.0, "le": 1.0})
    max_detections: int = field(default=50, metadata={"ge": 1})
    threads: int = field(default=1, metadata={"ge": 1, "le": 16})


@dataclass(frozen=True)
class Detection:
    """One detected landmark: box (x, y, w, h) in image px (top-left corner), category, score."""

    box: tuple[float, float, float, float]
    category: str
    score: float

    @property
    def centre_px(self) -> tuple[float, float]:
        """Box centre (u, v) in image pixels."""
        x, y, w, h = self.box
        return (x + w / 2, y + h / 2)


@dataclass(frozen=True)
class ModelInfo:
    """What the detector needs to know about a model, read from its graph and metadata."""

    input_name: str
    input_size: int
    output_names: tuple[str, ...]
    names: tuple[str, ...]
    strides: tuple[int, ...]
    anchors_px: tuple[np.ndarray, ...]


def _load_error(path: Path, err: Exception) -> DetectorError:
    """Turn an onnxruntime load failure into one line naming the file and the problem."""
    text = str(err)
    m = re.search(r"Opset (\d+) is under development.*?till opset (\d+)", text, re.S)
    if m:
        return DetectorError(f"{path}: unsupported ONNX opset {m.group(1)} "
                             f"(this onnxruntime supports ai.onnx opset <= {m.group(2)})")
    if "opset" in text.lower():
        return DetectorError(f"{path}: unsupported ONNX opset ({_first_line(text)})")
    if "ir version" in text.lower() or "ir_version" in text.lower():
        return DetectorError(f"{path}: unsupported ONNX IR version ({_first_line(text)})")
    if "protobuf" in text.lower():
        return DetectorError(f"{path}: not a valid ONNX model (corrupt or not a model file)")
    return DetectorError(f"{path}: cannot load ONNX model ({_first_line(text)})")


def _first_line(text: str, limit: int = 160) -> str:
    """First line of an error text, without onnxruntime's prefix, at most ``limit`` chars."""
    line = text.strip().splitlines()[0] if text.strip() else "unknown error"
    line = re.sub(r"^\[ONNXRuntimeError\]\s*:\s*\d+\s*:\s*\w+\s*:\s*", "", line)
    return line[:limit]


def _model_info(path: Path, session: object) -> ModelInfo:
    """Check the graph's input/outputs and the decoding metadata; raise DetectorError."""
    inputs = session.get_inputs()  # type: ignore[attr-defined]
    if len(inputs) != 1:
        raise DetectorError(f"{path}: expected one image input, the model has {len(inputs)}")
    shape = list(inputs[0].shape)
    ok = (len(shape) == 4 and (shape[0] == 1 or not isinstance(shape[0], int))
          and shape[1] == 3 and isinstance(shape[2], int) and shape[2] == shape[3]
          and shape[2] > 0 and shape[2] % 32 == 0)
    if not ok:
        raise DetectorError(f"{path}: wrong input shape {shape}, expected [1, 3, S, S] "
                            "with S a multiple of 32")
    meta = session.get_modelmeta().custom_metadata_map  # type: ignore[attr-defined]
    try:
        names = tuple(json.loads(meta["names"]))
        strides = tuple(int(s) for s in json.loads(meta["strides"]))
        anchors = tuple(np.asarray(a, np.float32).reshape(-1, 2)
                        for a in json.loads(meta["anchors"]))
    except (KeyError, ValueError, TypeError) as err:
        raise DetectorError(f"{path}: missing or bad detector metadata (names, strides, "
                            f"anchors): {err}") from err
    outputs = session.get_outputs()  # type: ignore[attr-defined]
    if len(outputs) != len(strides) or len(anchors) != len(strides):
        raise DetectorError(f"{path}: {len(outputs)} outputs for {len(strides)} strides "
                            f"and {len(anchors)} anchor sets")
    size = int(shape[2])
    for out, s, anc in zip(outputs, strides, anchors, strict=True):
        expect = [len(anc) * (5 + len(names)), size // s, size // s]
        if list(out.shape[1:]) != expect:
            raise DetectorError(f"{path}: output {out.name} has shape {out.shape}, "
                                f"expected [1, {', '.join(map(str, expect))}]")
    return ModelInfo(inputs[0].name, size, tuple(o.name for o in outputs), names, strides,
                     anchors)


class Detector:
    """YOLO-style landmark detector on onnxruntime (CPU).

    >>> det = Detector()                      # the committed model
    >>> dets = det.detect(frame_bgr)          # list[Detection], best score first
    """

    def __init__(self, model_path: str | Path | None = None,
                 config: DetectorConfig | None = None) -> None:
        import onnxruntime as ort

        self.config = config or DetectorConfig()
        chosen = model_path if model_path is not None else self.config.model_path
        self.model_path = Path(chosen) if chosen else DEFAULT_MODEL_PATH
        path = self.model_path
        if not path.exists():
            raise DetectorError(f"{path}: model file not found")
        if not path.is_file():
            raise DetectorError(f"{path}: not a file")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = self.config.threads
        opts.inter_op_num_threads = 1
        opts.log_severity_level = 3
        try:
            self._session = ort.InferenceSession(str(path), sess_options=opts,
                                                 providers=["CPUExecutionProvider"])
        except Exception as err:  # onnxruntime raises its own unexported exception types
            raise _load_error(path, err) from err
        self.info = _model_info(path, self._session)

    @property
    def categories(self) -> tuple[str, ...]:
        """Category name per class index."""
        return self.info.names

    def raw_outputs(self, image_bgr: np.ndarray) -> tuple[list[np.ndarray], Letterbox]:
        """Letterbox and run the network: raw head outputs (one image) and the letterbox."""
        _check_image(image_bgr)
        padded, lb = letterbox(image_bgr, self.info.input_size)
        x = (padded.astype(np.float32) * (1.0 / 255.0)).transpose(2, 0, 1)[None]
        outs = self._session.run(list(self.info.output_names), {self.info.input_name: x})
        return [np.asarray(o)[0] for o in outs], lb

    def detect(self, image_bgr: np.ndarray) -> list[Detection]:
        """Detect landmarks in a BGR uint8 frame; best score first."""
        raws, lb = self.raw_outputs(image_bgr)
        cfg = self.config
        boxes, scores, classes = decode(raws, list(self.info.anchors_px),
                                        list(self.info.strides), cfg.score_threshold)
        keep = class_aware_nms(boxes, scores, classes, cfg.nms_iou, cfg.max_detections)
        h, w = image_bgr.shape[:2]
        img_boxes = to_image_boxes(boxes[keep], lb, w, h)
        dets = []
        for (x0, y0, x1, y1), s, c in zip(img_boxes, scores[keep], classes[keep], strict=True):
            if x1 - x0 < 1 or y1 - y0 < 1:
                continue
            dets.append(Detection((float(x0), float(y0), float(x1 - x0), float(y1 - y0)),
                                  self.info.names[int(c)], float(s)))
        return dets


def _check_image(image_bgr: np.ndarray) -> None:
    """Raise ValueError unless ``image_bgr`` is an (H, W, 3) uint8 array."""
    if not isinstance(image_bgr, np.ndarray) or image_bgr.ndim != 3 or \
            image_bgr.shape[2] != 3 or image_bgr.dtype != np.uint8:
        shape = getattr(image_bgr, "shape", None)
        dtype = getattr(image_bgr, "dtype", type(image_bgr).__name__)
        raise ValueError(f"image_bgr: expected an (H, W, 3) uint8 array, got {shape} {dtype}")
    if image_bgr.shape[0] < 1 or image_bgr.shape[1] < 1:
        raise ValueError(f"image_bgr: empty image {image_bgr.shape}")


def match_detection(detections: list[Detection], category: str,
                    expected_centre_px: tuple[float, float] | None = None,
                    gate_px: float = float("inf")) -> Detection | None:
    """The detection to (re)start a tracker on a landmark of ``category``.

    Among detections of that category whose centre lies within ``gate_px`` of the landmark's
    expected image position (its map position projected with the current pose; None = no
    prior, e.g. first acquisition), take the nearest; ties (or no prior) go to the best score.
    """
    best: Detection | None = None
    best_key = (float("inf"), 0.0)
    for d in detections:
        if d.category != category:
            continue
        dist = 0.0
        if expected_centre_px is not None:
            cx, cy = d.centre_px
            dist = float(np.hypot(cx - expected_centre_px[0], cy - expected_centre_px[1]))
            if dist > gate_px:
                continue
        key = (dist, -d.score)
        if key < best_key:
            best, best_key = d, key
    return best
