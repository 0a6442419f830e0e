"""Rewrite the committed regression baseline (tests/tracker/regression_baseline.json).

Run after an intended accuracy change:

    PYTHONPATH=. python benchmarks/tracker_regression_baseline.py
"""

from __future__ import annotations

import json

from companion.evaluation.regression import BASELINE_PATH, regression_scores


def main() -> None:
    scores = regression_scores()
    BASELINE_PATH.write_text(json.dumps(scores, indent=2, sort_keys=True) + "\n")
    print(json.dumps(scores, indent=2, sort_keys=True))
    print(f"wrote {BASELINE_PATH}")


if __name__ == "__main__":
    main()
