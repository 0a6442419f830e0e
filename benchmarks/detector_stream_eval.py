"""Detector accuracy on recorded streams with truth (e.g. written by ``companion synth``).

    PYTHONPATH=. /work/main/.venv/bin/python benchmarks/detector_stream_eval.py \
        --stream /tmp/sim_survey --landmarks config/landmarks.geojson [--model M.onnx ...]

A truth box counts when the landmark is at least 90 % in view and at most 10 % occluded
(``in_view_frac``/``occluded_frac`` columns, when present); detections overlapping a box
that does not count (IoU >= 0.3) are ignored rather than scored as false positives.
Categories come from the landmark map.  Prints mAP@0.5 and recall/precision at the default
score threshold, per model, on all the streams together.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from detector_eval import SMALL_PX, average_precision, match  # the script folder is on sys.path

from tracker.detector import Detector, DetectorConfig
from tracker.detector_decode import iou_one_to_many
from training.synth_data import CATEGORIES, Scene

Frame = tuple[Scene, np.ndarray]  # scene with counted truth, ignored boxes (x0, y0, x1, y1)


def load_stream(folder: Path, categories: dict[str, str]) -> list[Frame]:
    """Frames with truth from a stream folder (frames.csv, truth_boxes.csv)."""
    truth: dict[int, list[dict[str, str]]] = defaultdict(list)
    with (folder / "truth_boxes.csv").open() as f:
        for row in csv.DictReader(f):
            truth[int(row["index"])].append(row)
    frames = []
    with (folder / "frames.csv").open() as f:
        for row in csv.DictReader(f):
            image = cv2.imread(str(folder / row["file"]), cv2.IMREAD_COLOR)
            keep, ignore, cls = [], [], []
            for t in truth[int(row["index"])]:
                box = [float(t[k]) for k in ("x", "y", "w", "h")]
                full = (float(t.get("in_view_frac", 1)) >= 0.9
                        and float(t.get("occluded_frac", 0)) <= 0.1)
                category = categories.get(t["landmark_id"], "")
                if full and category in CATEGORIES:
                    keep.append(box)
                    cls.append(CATEGORIES.index(category))
                else:
                    ignore.append([box[0], box[1], box[0] + box[2], box[1] + box[3]])
            frames.append((Scene(image, np.array(keep, np.float32).reshape(-1, 4),
                                 np.array(cls, np.int64)), np.array(ignore).reshape(-1, 4)))
    return frames


def evaluate(det: Detector, frames: list[Frame], threshold: float) -> dict[str, float]:
    """mAP@0.5 (classes present in the truth) and recall/precision at ``threshold``."""
    per_cls: dict[str, list[tuple[float, bool]]] = defaultdict(list)
    n_truth: dict[str, int] = defaultdict(int)
    found = total = n_kept = n_tp = small = small_found = 0
    for scene, ignore in frames:
        dets = []
        for d in det.detect(scene.image_bgr):
            x, y, w, h = d.box
            if len(ignore) and iou_one_to_many(np.array([x, y, x + w, y + h]),
                                               ignore).max() >= 0.3:
                continue
            dets.append(d)
        dets.sort(key=lambda d: -d.score)
        tp, _ = match(dets, scene)
        for d, t in zip(dets, tp, strict=True):
            per_cls[d.category].append((d.score, bool(t)))
        for c in scene.classes:
            n_truth[CATEGORIES[int(c)]] += 1
        kept = [d for d in dets if d.score >= threshold]
        tp_k, used = match(kept, scene)
        n_kept += len(kept)
        n_tp += int(tp_k.sum())
        found += int(used.sum())
        total += len(used)
        is_small = np.max(scene.boxes_xywh[:, 2:], axis=1) <= SMALL_PX
        small += int(is_small.sum())
        small_found += int(used[is_small].sum())
    aps = {c: average_precision(np.array([s for s, _ in per_cls[c]]),
                                np.array([t for _, t in per_cls[c]], bool), n)
           for c, n in n_truth.items() if n}
    return {"mAP50": float(np.mean(list(aps.values()))) if aps else float("nan"),
            **{f"AP50_{c}": a for c, a in aps.items()},
            "recall": found / max(1, total), "precision": n_tp / max(1, n_kept),
            "n_truth": total, "n_small": small,
            "recall_small": small_found / max(1, small)}


def main() -> None:
    """Evaluate each model on all the given streams."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--stream", type=Path, action="append", required=True)
    ap.add_argument("--landmarks", type=Path, required=True)
    ap.add_argument("--model", action="append", default=None)
    ap.add_argument("--threshold", type=float, default=DetectorConfig().score_threshold)
    args = ap.parse_args()
    geo = json.loads(args.landmarks.read_text())
    categories = {str(f["id"]): f["properties"]["category"] for f in geo["features"]}
    frames = [fr for s in args.stream for fr in load_stream(s, categories)]
    print(f"streams: {', '.join(s.name for s in args.stream)}: {len(frames)} frames")
    for model in args.model or [None]:
        det = Detector(model, DetectorConfig(score_threshold=0.01, max_detections=100))
        print(f"model {det.model_path.name}")
        for k, v in evaluate(det, frames, args.threshold).items():
            print(f"  {k}: {v:.3f}" if isinstance(v, float) else f"  {k}: {v}")
        print(f"  recall/precision at score >= {args.threshold}")


if __name__ == "__main__":
    main()
