"""Detector scoring for the benchmarks and tests (VOC mAP@0.5, recall, timing) and the
held-out frames they score.

A frame to score is an :class:`EvalFrame`: the image, the truth boxes that count (x, y, w, h
px, top-left) with their class indices, and boxes (x0, y0, x1, y1) to ignore: a detection
overlapping an ignored box (IoU >= 0.3) is neither a hit nor a false alarm.
"""

from __future__ import annotations

import statistics
import time
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from tracker.detector import Detection, Detector
from tracker.detector_decode import iou_one_to_many
from training.sim_data import SMALL_PX, sim_scene
from training.synth_data import CATEGORIES, render_scene

IGNORE_IOU = 0.3
SIM_SEED = 1_000_000  # held-out simulated frames use seeds from here (the pool: 1..N)
COUNT_IN_VIEW, COUNT_HIDDEN = 0.9, 0.1  # a face counts when this much in view, unhidden


@dataclass(frozen=True)
class EvalFrame:
    """An image, its counted truth and the boxes to ignore."""

    image_bgr: np.ndarray
    boxes_xywh: np.ndarray  # (N, 4)
    classes: np.ndarray  # (N,) indices into CATEGORIES
    ignore_xyxy: np.ndarray  # (M, 4)


def sim_frame(seed: int) -> EvalFrame:
    """One held-out simulated-world frame (640x480) and what counts in it."""
    s = sim_scene(np.random.default_rng(seed))
    keep, rest = s.split(COUNT_IN_VIEW, COUNT_HIDDEN)
    b = s.boxes_xywh[rest]
    ignore = np.column_stack([b[:, :2], b[:, :2] + b[:, 2:]]).reshape(-1, 4)
    return EvalFrame(s.image_bgr, s.boxes_xywh[keep], s.classes[keep], ignore)


def procedural_frame(seed: int) -> EvalFrame:
    """One held-out procedural frame (416x416), every box counted."""
    s = render_scene(np.random.default_rng(seed), 416, 416)
    return EvalFrame(s.image_bgr, s.boxes_xywh, s.classes, np.zeros((0, 4)))


def held_out(kind: str, frames: int, seed: int) -> list[EvalFrame]:
    """Held-out frames (``kind`` "sim" or "procedural"), frame i seeded ``seed + i``."""
    make = sim_frame if kind == "sim" else procedural_frame
    return [make(seed + i) for i in range(frames)]


def _xyxy(box: tuple[float, float, float, float] | np.ndarray) -> np.ndarray:
    x, y, w, h = box
    return np.array([x, y, x + w, y + h], np.float64)


def match(dets: list[Detection], frame: EvalFrame) -> tuple[np.ndarray, np.ndarray]:
    """Greedy matching by score (``dets`` best first), same category, IoU >= 0.5 (VOC).

    Returns per-detection true-positive flags and per-truth matched flags.
    """
    gt = np.array([_xyxy(b) for b in frame.boxes_xywh]).reshape(-1, 4)
    gt_cls = [CATEGORIES[int(c)] for c in frame.classes]
    used = np.zeros(len(gt), bool)
    tp = np.zeros(len(dets), bool)
    for k, d in enumerate(dets):
        if not len(gt):
            break
        iou = iou_one_to_many(_xyxy(d.box), gt)
        iou[[c != d.category for c in gt_cls]] = 0.0
        iou[used] = 0.0
        j = int(np.argmax(iou))
        if iou[j] >= 0.5:
            used[j] = True
            tp[k] = True
    return tp, used


def average_precision(scores: np.ndarray, tp: np.ndarray, n_truth: int) -> float:
    """VOC all-point interpolated AP: area under the monotone precision-recall envelope."""
    if n_truth == 0:
        return float("nan")
    order = np.argsort(-scores, kind="stable")
    ctp = np.cumsum(tp[order])
    recall = ctp / n_truth
    precision = ctp / np.arange(1, len(order) + 1)
    r = np.concatenate([[0.0], recall, [1.0]])
    p = np.concatenate([[1.0], precision, [0.0]])
    p = np.maximum.accumulate(p[::-1])[::-1]  # p_interp(r) = max_{r' >= r} p(r')
    return float(np.sum((r[1:] - r[:-1]) * p[1:]))


def _scored(det: Detector, frame: EvalFrame) -> list[Detection]:
    """The detector's detections, best first, less those on ignored boxes."""
    out = []
    for d in det.detect(frame.image_bgr):
        if len(frame.ignore_xyxy) and float(
                iou_one_to_many(_xyxy(d.box), frame.ignore_xyxy).max()) >= IGNORE_IOU:
            continue
        out.append(d)
    return sorted(out, key=lambda d: -d.score)


def evaluate(det: Detector, frames: list[EvalFrame], threshold: float,
             found: list[tuple[bool, bool]] | None = None) -> dict[str, float]:
    """mAP@0.5 over all detections (the detector's own threshold should be low), AP per
    category present, and recall (all, small, large) and precision at ``threshold``.

    ``found``: if given, gets (small, found at ``threshold``) for every counted landmark,
    in order, so that two models can be compared landmark by landmark.
    """
    per_cls: dict[str, list[tuple[float, bool]]] = defaultdict(list)
    n_truth: dict[str, int] = defaultdict(int)
    hits = {"small": [0, 0], "large": [0, 0]}
    n_kept = n_tp = 0
    for frame in frames:
        dets = _scored(det, frame)
        tp, _ = match(dets, frame)
        for d, t in zip(dets, tp, strict=True):
            per_cls[d.category].append((d.score, bool(t)))
        for c in frame.classes:
            n_truth[CATEGORIES[int(c)]] += 1
        kept = [d for d in dets if d.score >= threshold]
        tp_k, used = match(kept, frame)
        n_kept += len(kept)
        n_tp += int(tp_k.sum())
        for b, u in zip(frame.boxes_xywh, used, strict=True):
            key = "small" if max(b[2], b[3]) <= SMALL_PX else "large"
            hits[key][0] += int(u)
            hits[key][1] += 1
            if found is not None:
                found.append((key == "small", bool(u)))
    aps = {c: average_precision(np.array([s for s, _ in per_cls[c]]),
                                np.array([t for _, t in per_cls[c]], bool), n)
           for c, n in sorted(n_truth.items()) if n}
    total = hits["small"][1] + hits["large"][1]
    return {"mAP50": float(np.mean(list(aps.values()))) if aps else float("nan"),
            **{f"AP50_{c}": a for c, a in aps.items()},
            "recall": (hits["small"][0] + hits["large"][0]) / max(1, total),
            "precision": n_tp / max(1, n_kept),
            "recall_small": hits["small"][0] / max(1, hits["small"][1]),
            "recall_large": hits["large"][0] / max(1, hits["large"][1]),
            "n_small": hits["small"][1], "n_large": hits["large"][1]}


def timing(det: Detector, image: np.ndarray, runs: int) -> tuple[float, float]:
    """Median ms of the network alone and of a whole detect() call."""
    det.detect(image)
    net, full = [], []
    for _ in range(runs):
        t0 = time.perf_counter()
        det.raw_outputs(image)
        t1 = time.perf_counter()
        det.detect(image)
        t2 = time.perf_counter()
        net.append((t1 - t0) * 1e3)
        full.append((t2 - t1) * 1e3)
    return statistics.median(net), statistics.median(full)


def print_block(name: str, metrics: dict[str, float], threshold: float) -> None:
    """One model's figures, one per line."""
    print(name)
    for k, v in metrics.items():
        print(f"  {k}: {v:.3f}" if isinstance(v, float) else f"  {k}: {v}")
    print(f"  recall/precision at score >= {threshold}")
