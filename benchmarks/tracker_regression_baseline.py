"""Rewrite the committed regression baseline (tests/tracker/regression_baseline.json).

Run after an intended accuracy change:

    PYTHONPATH=. python benchmarks/tracker_regression_baseline.py
"""

from __future__ import annotations

import json
from pathlib import Path

from companion.evaluation.regression import regression_scores

#: The test's fixture (tests/tracker/test_tracker_regression.py reads it).
BASELINE_PATH = Path(__file__).resolve().parents[1] / "tests/tracker/regression_baseline.json"


def main() -> None:
    scores = regression_scores()
    BASELINE_PATH.write_text(json.dumps(scores, indent=2, sort_keys=True) + "\n")
    print(json.dumps(scores, indent=2, sort_keys=True))
    print(f"wrote {BASELINE_PATH}")


if __name__ == "__main__":
    main()
