"""Accuracy regression gate: success AUC must not drop > 0.02 below the committed baseline."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from companion.evaluation.regression import TOLERANCE_AUC, regression_scores

#: Written by benchmarks/tracker_regression_baseline.py.
BASELINE_PATH = Path(__file__).with_name("regression_baseline.json")


@pytest.fixture(scope="module")
def scores() -> dict[str, dict[str, float]]:
    return regression_scores()


def test_baseline_covers_every_case(scores: dict[str, dict[str, float]]) -> None:
    baseline = json.loads(BASELINE_PATH.read_text())
    assert set(baseline) == set(scores)
    for case in scores:
        assert set(baseline[case]) == set(scores[case])


def test_success_auc_has_not_regressed(scores: dict[str, dict[str, float]]) -> None:
    baseline = json.loads(BASELINE_PATH.read_text())
    drops = {
        f"{case}/{name}": (baseline[case][name], auc)
        for case, per in scores.items()
        for name, auc in per.items()
        if auc < baseline[case][name] - TOLERANCE_AUC
    }
    assert not drops, f"success AUC dropped (baseline, now): {drops}"


def test_adaptive_beats_the_plain_particle_filter(scores: dict[str, dict[str, float]]) -> None:
    """The paper's claim on the simulated sequences: 20 adaptive particles beat 120 plain ones."""
    for case, per in scores.items():
        assert per["adaptive"] > per["pf"], f"{case}: {per}"
