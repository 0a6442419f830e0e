"""Pure numpy pre- and post-processing for the YOLO-style landmark detector.

Letterboxing (keep aspect, pad to a square network input), decoding of the raw head outputs
of two or three scales, and class-aware non-maximum suppression.  No onnxruntime here, so
every function is testable on synthetic arrays.

Box decoding (YOLOv5 convention, the one the training loss uses), per cell (i, j), anchor a,
stride s, raw logits t and sigma the logistic function::

    cx = (2 sigma(tx) - 0.5 + j) s        cy = (2 sigma(ty) - 0.5 + i) s
    w  = (2 sigma(tw))^2 anchor_w         h  = (2 sigma(th))^2 anchor_h
    score_c = sigma(t_obj) sigma(t_c)
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

PAD_VALUE = 114


@dataclass(frozen=True)
class Letterbox:
    """How an image was fitted into the square network input: x_in = x_img * scale + pad."""

    scale: float
    pad_x_px: float
    pad_y_px: float


def letterbox(image_bgr: np.ndarray, size: int) -> tuple[np.ndarray, Letterbox]:
    """Resize keeping the aspect ratio and pad to ``size`` x ``size`` (grey, centred)."""
    h, w = image_bgr.shape[:2]
    scale = min(size / w, size / h)
    nw, nh = round(w * scale), round(h * scale)
    resized = image_bgr if (nw, nh) == (w, h) else cv2.resize(
        image_bgr, (nw, nh), interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    pad_x, pad_y = (size - nw) // 2, (size - nh) // 2
    out = np.full((size, size, 3), PAD_VALUE, np.uint8)
    out[pad_y:pad_y + nh, pad_x:pad_x + nw] = resized
    return out, Letterbox(scale, float(pad_x), float(pad_y))


def to_image_boxes(boxes_xyxy: np.ndarray, lb: Letterbox, width: int,
                   height: int) -> np.ndarray:
    """Map (N, 4) x0, y0, x1, y1 boxes from network input to image pixels, clipped to it."""
    out = np.empty_like(boxes_xyxy, dtype=np.float64)
    out[:, [0, 2]] = (boxes_xyxy[:, [0, 2]] - lb.pad_x_px) / lb.scale  # x = (x_in - pad) / s
    out[:, [1, 3]] = (boxes_xyxy[:, [1, 3]] - lb.pad_y_px) / lb.scale
    out[:, [0, 2]] = out[:, [0, 2]].clip(0, width)
    out[:, [1, 3]] = out[:, [1, 3]].clip(0, height)
    return out


def to_input_boxes(boxes_xyxy: np.ndarray, lb: Letterbox) -> np.ndarray:
    """Map (N, 4) image-pixel boxes into network-input pixels (inverse of to_image_boxes)."""
    out = np.asarray(boxes_xyxy, np.float64) * lb.scale
    out[:, [0, 2]] += lb.pad_x_px
    out[:, [1, 3]] += lb.pad_y_px
    return out


def sigmoid(x: np.ndarray) -> np.ndarray:
    """Logistic function, computed without overflow for large negative logits."""
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def decode_head(raw: np.ndarray, anchors_px: np.ndarray,
                stride: int) -> tuple[np.ndarray, np.ndarray]:
    """Decode one head.

    raw: (A*(5+C), H, W) logits for one image; anchors_px: (A, 2) anchor w, h in input px.
    Returns boxes (A*H*W, 4) as x0, y0, x1, y1 input px and class scores (A*H*W, C).
    """
    na = len(anchors_px)
    ch, gh, gw = raw.shape
    if ch % na or ch // na < 6:
        raise ValueError(f"raw: expected A*(5+C) channels with A={na}, C>=1, got {ch}")
    p = sigmoid(raw.reshape(na, ch // na, gh, gw).astype(np.float32))
    gy, gx = np.meshgrid(np.arange(gh), np.arange(gw), indexing="ij")
    cx = (2 * p[:, 0] - 0.5 + gx) * stride
    cy = (2 * p[:, 1] - 0.5 + gy) * stride
    w = (2 * p[:, 2]) ** 2 * anchors_px[:, 0, None, None]
    h = (2 * p[:, 3]) ** 2 * anchors_px[:, 1, None, None]
    boxes = np.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], -1).reshape(-1, 4)
    scores = (p[:, 4:5] * p[:, 5:]).transpose(0, 2, 3, 1).reshape(-1, ch // na - 5)
    return boxes, scores


def decode(raws: list[np.ndarray], anchors_px: list[np.ndarray], strides: list[int],
           score_threshold: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Decode every head; keep (box, class) pairs scoring >= ``score_threshold``.

    Returns boxes (N, 4) x0, y0, x1, y1 input px, scores (N,), class ids (N,).
    """
    all_boxes, all_scores, all_cls = [], [], []
    for raw, anc, s in zip(raws, anchors_px, strides, strict=True):
        boxes, scores = decode_head(raw, np.asarray(anc, np.float32), s)
        idx, cls = np.nonzero(scores >= score_threshold)
        all_boxes.append(boxes[idx])
        all_scores.append(scores[idx, cls])
        all_cls.append(cls)
    return (np.concatenate(all_boxes).reshape(-1, 4), np.concatenate(all_scores),
            np.concatenate(all_cls).astype(np.int64))


def iou_one_to_many(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """IoU of one x0, y0, x1, y1 box with each row of ``boxes``."""
    iw = (np.minimum(box[2], boxes[:, 2]) - np.maximum(box[0], boxes[:, 0])).clip(0)
    ih = (np.minimum(box[3], boxes[:, 3]) - np.maximum(box[1], boxes[:, 1])).clip(0)
    inter = iw * ih
    area = (box[2] - box[0]) * (box[3] - box[1])
    areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    return inter / np.maximum(area + areas - inter, 1e-9)


def nms(boxes: np.ndarray, scores: np.ndarray, iou_threshold: float) -> np.ndarray:
    """Greedy NMS: indices of kept boxes, best score first."""
    order = np.argsort(-scores, kind="stable")
    keep: list[int] = []
    while order.size:
        i = int(order[0])
        keep.append(i)
        rest = order[1:]
        order = rest[iou_one_to_many(boxes[i], boxes[rest]) <= iou_threshold]
    return np.array(keep, np.int64)


def class_aware_nms(boxes: np.ndarray, scores: np.ndarray, classes: np.ndarray,
                    iou_threshold: float, max_detections: int,
                    max_candidates: int = 1000) -> np.ndarray:
    """NMS within each class only (boxes of different classes never suppress each other).

    Only the ``max_candidates`` best-scoring boxes enter NMS (bounds the time on a frame full
    of weak responses).  Returns indices of kept boxes, best score first, at most
    ``max_detections``.
    """
    cand = np.argsort(-scores, kind="stable")[:max_candidates]
    keep = [cand[classes[cand] == c][nms(boxes[cand][classes[cand] == c],
                                         scores[cand][classes[cand] == c], iou_threshold)]
            for c in np.unique(classes[cand])]
    kept = np.concatenate(keep) if keep else np.zeros(0, np.int64)
    return kept[np.argsort(-scores[kept], kind="stable")][:max_detections]
