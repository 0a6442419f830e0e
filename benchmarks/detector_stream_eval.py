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

from tracker.detector import Detector, DetectorConfig
from training.evaluation import EvalFrame, evaluate, print_block
from training.synth_data import CATEGORIES


def load_stream(folder: Path, categories: dict[str, str]) -> list[EvalFrame]:
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
            frames.append(EvalFrame(image, np.array(keep, np.float32).reshape(-1, 4),
                                    np.array(cls, np.int64), np.array(ignore).reshape(-1, 4)))
    return frames


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
        print_block(f"model {det.model_path.name}", evaluate(det, frames, args.threshold),
                    args.threshold)


if __name__ == "__main__":
    main()
