"""Detector accuracy and speed on a held-out set (the issue's mAP@0.5 and small-landmark recall).

    PYTHONPATH=. .venv/bin/python benchmarks/detector_eval.py \
        [--model A.onnx --model B.onnx] [--set sim|procedural] [--frames 400] [--check]

``--set sim`` (default): 640x480 frames of random streets of the simulated world
(:func:`training.sim_data.sim_scene`, seeds ``--seed`` + i; the training pool uses seeds
1..N, the held-out set 1,000,000 and up), fed whole to ``Detector.detect`` (letterboxed to
416). A landmark counts when at least 90 % of its face is in the image and at most 10 % is
hidden behind a nearer one; detections on the others are ignored. Small means the larger
side of its box is <= 32 px in the 640x480 frame. ``--set procedural``: the older
procedural 416x416 scenes of :mod:`training.synth_data`.

Prints, per model: mAP@0.5 (VOC all-point AP, mean over categories), AP per category,
recall and precision at the configured score threshold, recall on small and on larger
landmarks, and time per frame on one thread (median; network only and the whole
``detect`` call). With two models, the landmarks found by one and not the other (small and
larger apart, with a sign test). ``--check`` exits 1 when a model's mAP@0.5 or small recall
falls more than 0.02 below ``benchmarks/detector_baseline.json`` (the committed model's).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from tracker.detector import Detector, DetectorConfig
from training.evaluation import SIM_SEED, evaluate, held_out, print_block, timing

BASELINE = Path(__file__).with_name("detector_baseline.json")
TOLERANCE = 0.02


def paired(a: np.ndarray, b: np.ndarray) -> None:
    """Landmarks found by one of two models and not by the other (McNemar's discordant
    pairs), small and larger apart: the difference that is the models', not the frames'."""
    for name, sel in (("small", a[:, 0]), ("larger", ~a[:, 0])):
        only_a = int(np.sum(a[sel, 1] & ~b[sel, 1]))
        only_b = int(np.sum(b[sel, 1] & ~a[sel, 1]))
        n = only_a + only_b
        # two-sided exact binomial (sign) test of only_a vs only_b
        k = min(only_a, only_b)
        p = min(1.0, 2.0 * sum(math.comb(n, i) for i in range(k + 1)) / 2.0**n) if n else 1.0
        print(f"{name} landmarks found by the first model only: {only_a}, by the second only: "
              f"{only_b} (sign test p = {p:.3f})")


def main() -> int:
    """Evaluate each model on the same held-out frames and print one block per model."""
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", action="append", default=None)
    ap.add_argument("--set", choices=("sim", "procedural"), default="sim")
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--seed", type=int, default=None,
                    help=f"first seed (default {SIM_SEED} for sim, 1000 for procedural)")
    ap.add_argument("--threshold", type=float, default=DetectorConfig().score_threshold)
    ap.add_argument("--runs", type=int, default=50, help="timed detect() calls")
    ap.add_argument("--check", action="store_true", help="gate against the baseline file")
    ap.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = ap.parse_args()
    seed = args.seed if args.seed is not None else (SIM_SEED if args.set == "sim" else 1000)
    frames = held_out(args.set, args.frames, seed)
    n = sum(len(f.classes) for f in frames)
    h, w = frames[0].image_bgr.shape[:2]
    print(f"held-out {args.set}: {len(frames)} frames {w}x{h}, {n} landmarks counted, "
          f"seeds {seed}..{seed + args.frames - 1}", flush=True)
    results, failed, found = {}, False, []
    base = json.loads(BASELINE.read_text())[args.set] if args.check else {}
    for model in args.model or [None]:
        det = Detector(model, DetectorConfig(score_threshold=0.01, max_detections=100,
                                             threads=1))
        found.append([])
        m = evaluate(det, frames, args.threshold, found[-1])
        net_ms, full_ms = timing(det, frames[0].image_bgr, args.runs)
        m |= {"network_ms": net_ms, "detect_ms": full_ms}
        print_block(f"model {det.model_path.name} ({det.model_path.stat().st_size / 1e6:.2f} MB,"
                    f" strides {list(det.info.strides)})", m, args.threshold)
        results[str(det.model_path)] = m
        for key in ("mAP50", "recall_small"):
            if key in base and m[key] < base[key] - TOLERANCE:
                print(f"  REGRESSION: {key} {m[key]:.3f} < baseline {base[key]:.3f} - "
                      f"{TOLERANCE}")
                failed = True
    if len(found) == 2:
        paired(np.array(found[0]), np.array(found[1]))
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
