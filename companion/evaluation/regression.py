"""The accuracy regression gate: short deterministic sequences and a committed baseline.

``python benchmarks/tracker_regression_baseline.py`` rewrites the baseline JSON
(``tests/tracker/regression_baseline.json``: a test fixture, which the installed package
never reads) after an intended change; ``tests/tracker/test_tracker_regression.py`` fails
when a tracker's success AUC on any case drops by more than :data:`TOLERANCE_AUC` below it.
"""

from __future__ import annotations

from companion.evaluation.runner import make_tracker, run_frames
from companion.evaluation.sequences import Sequence
from companion.evaluation.synthetic import SynthSpec, generate

TOLERANCE_AUC = 0.02
CASES: dict[str, SynthSpec] = {
    "illumination": SynthSpec(frames=80, width_px=320, height_px=240, seed=11),
    "occlusion": SynthSpec(
        frames=80, width_px=320, height_px=240, illumination=False, hidden_frames=(30, 42), seed=5
    ),
}
TRACKERS = ("adaptive", "pf")


def regression_scores() -> dict[str, dict[str, float]]:
    """Success AUC of each gated tracker on each case: {case: {tracker: auc}}."""
    out: dict[str, dict[str, float]] = {}
    for case, spec in CASES.items():
        frames, truth = generate(spec)
        seq = Sequence(case, (), truth)
        out[case] = {
            name: round(run_frames(make_tracker(name, 0), name, seq, frames).scores.success_auc, 4)
            for name in TRACKERS
        }
    return out
