"""The committed model against its recorded accuracy (a regression gate, not the benchmark).

``benchmarks/detector_baseline.json`` holds what the committed model scored when it was
committed: on 400 held-out simulated frames (the benchmark, docs/detector.md) and on the
first 40 of them (this test, so that it runs in seconds). A change to the model, the
decoding, the letterbox or the simulated world that costs accuracy fails here.
"""

from __future__ import annotations

import json
from pathlib import Path

from tracker.detector import Detector, DetectorConfig
from training.evaluation import SIM_SEED, evaluate, held_out

BASELINE = Path(__file__).resolve().parents[2] / "benchmarks" / "detector_baseline.json"
TOLERANCE = 0.02


def test_the_committed_model_keeps_its_accuracy_on_held_out_simulated_frames() -> None:
    base = json.loads(BASELINE.read_text())["test_sim_40"]
    det = Detector(config=DetectorConfig(score_threshold=0.01, max_detections=100))
    m = evaluate(det, held_out("sim", base["frames"], SIM_SEED), DetectorConfig().score_threshold)
    assert m["n_small"] + m["n_large"] == base["landmarks"]  # the same frames as recorded
    assert m["mAP50"] >= base["mAP50"] - TOLERANCE, m
    assert m["recall"] >= base["recall"] - TOLERANCE, m
