"""Detector accuracy and speed on a held-out set of procedural scenes.

    PYTHONPATH=. /work/main/.venv/bin/python benchmarks/detector_eval.py \
        [--model A.onnx --model B.onnx] [--frames 300] [--seed 1000]

Prints, per model: mAP@0.5 (VOC all-point AP, mean over categories), recall and precision at
the configured score threshold, recall on small landmarks (larger box side <= 32 px) and on
the others, and inference time per 416x416 frame on one thread (median; network only and the
whole ``detect`` call).  The held-out frames use seeds the training pool never uses (the pool
uses seed 1; held-out frames use ``--seed`` + frame index).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tracker.detector import Detection, Detector, DetectorConfig
from tracker.detector_decode import iou_one_to_many
from training.synth_data import CATEGORIES, Scene, render_scene

SMALL_PX = 32.0


def held_out(frames: int, seed: int, size: int) -> list[Scene]:
    """The held-out scenes: one generator per frame, seeded ``seed + i``."""
    return [render_scene(np.random.default_rng(seed + i), size, size) for i in range(frames)]


def _xyxy(box: tuple[float, float, float, float] | np.ndarray) -> np.ndarray:
    x, y, w, h = box
    return np.array([x, y, x + w, y + h], np.float64)


def match(dets: list[Detection], scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Greedy matching by score, same category, IoU >= 0.5 (VOC).

    Returns per-detection true-positive flags and per-truth matched flags.
    """
    gt = np.array([_xyxy(b) for b in scene.boxes_xywh]).reshape(-1, 4)
    gt_cls = [CATEGORIES[int(c)] for c in scene.classes]
    used = np.zeros(len(gt), bool)
    tp = np.zeros(len(dets), bool)
    for k, d in enumerate(sorted(dets, key=lambda d: -d.score)):
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


def evaluate(det: Detector, scenes: list[Scene], threshold: float) -> dict[str, float]:
    """mAP@0.5 over all detections (det's threshold should be low) and recall at ``threshold``."""
    per_cls: dict[str, list[tuple[float, bool]]] = {c: [] for c in CATEGORIES}
    n_truth = dict.fromkeys(CATEGORIES, 0)
    hits = {"small": [0, 0], "large": [0, 0]}
    n_pos_dets = n_tp_dets = 0
    for scene in scenes:
        dets = sorted(det.detect(scene.image_bgr), key=lambda d: -d.score)
        tp, _ = match(dets, scene)
        for d, t in zip(dets, tp, strict=True):
            per_cls[d.category].append((d.score, bool(t)))
        for c in scene.classes:
            n_truth[CATEGORIES[int(c)]] += 1
        kept = [d for d in dets if d.score >= threshold]
        tp_k, used_k = match(kept, scene)
        n_pos_dets += len(kept)
        n_tp_dets += int(tp_k.sum())
        for b, u in zip(scene.boxes_xywh, used_k, strict=True):
            key = "small" if max(b[2], b[3]) <= SMALL_PX else "large"
            hits[key][0] += int(u)
            hits[key][1] += 1
    aps = {c: average_precision(np.array([s for s, _ in v]), np.array([t for _, t in v]),
                                n_truth[c]) for c, v in per_cls.items()}
    total = hits["small"][1] + hits["large"][1]
    return {"mAP50": float(np.nanmean(list(aps.values()))),
            **{f"AP50_{c}": a for c, a in aps.items()},
            "recall": (hits["small"][0] + hits["large"][0]) / max(1, total),
            "precision": n_tp_dets / max(1, n_pos_dets),
            "recall_small": hits["small"][0] / max(1, hits["small"][1]),
            "recall_large": hits["large"][0] / max(1, hits["large"][1]),
            "n_small": hits["small"][1], "n_large": hits["large"][1]}


def timing(det: Detector, image: np.ndarray, runs: int) -> tuple[float, float]:
    """Median ms of the network alone and of a whole detect() call, one thread."""
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


def main() -> None:
    """Evaluate each model on the same held-out scenes and print one block per model."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--model", action="append", default=None)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--size", type=int, default=416)
    ap.add_argument("--threshold", type=float, default=DetectorConfig().score_threshold)
    ap.add_argument("--runs", type=int, default=50)
    args = ap.parse_args()
    scenes = held_out(args.frames, args.seed, args.size)
    n_small = sum(int(max(b[2], b[3]) <= SMALL_PX) for s in scenes for b in s.boxes_xywh)
    print(f"held-out: {len(scenes)} frames {args.size}x{args.size}, "
          f"{sum(len(s.classes) for s in scenes)} landmarks ({n_small} small <= {SMALL_PX:g} px),"
          f" seeds {args.seed}..{args.seed + args.frames - 1}")
    for model in args.model or [None]:
        det = Detector(model, DetectorConfig(score_threshold=0.01, max_detections=100,
                                             threads=1))
        m = evaluate(det, scenes, args.threshold)
        net_ms, full_ms = timing(det, scenes[0].image_bgr, args.runs)
        print(f"model {det.model_path.name} ({det.model_path.stat().st_size / 1e6:.2f} MB, "
              f"strides {list(det.info.strides)})")
        for k, v in m.items():
            print(f"  {k}: {v:.3f}" if isinstance(v, float) else f"  {k}: {v}")
        print(f"  recall/precision at score >= {args.threshold}")
        print(f"  inference ms/frame (1 thread, median of {args.runs}): network {net_ms:.1f}, "
              f"detect() {full_ms:.1f}")


if __name__ == "__main__":
    main()
