"""The ``companion eval`` report: a markdown table and PNG plots per sequence."""

from __future__ import annotations

import json
from collections.abc import Sequence as Seq
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from companion.evaluation.metrics import (
    PRECISION_THRESHOLDS_PX,
    SUCCESS_THRESHOLDS,
    boxes_array,
    centre_errors,
    ious,
    precision_curve,
    success_curve,
    visible,
)
from companion.evaluation.plots import Series, likelihood_panel, line_plot
from companion.evaluation.runner import RunResult
from companion.evaluation.sequences import Sequence
from tracker import AdaptiveTracker
from tracker.features import feature_name

COLUMNS = (
    ("sequence", "sequence", "{}"),
    ("tracker", "tracker", "{}"),
    ("frames", "frames", "{}"),
    ("mean_centre_error_px", "mean err px", "{:.1f}"),
    ("median_centre_error_px", "median err px", "{:.1f}"),
    ("precision_20px", "prec@20", "{:.3f}"),
    ("success_auc", "AUC", "{:.3f}"),
    ("frames_lost", "lost", "{}"),
    ("median_ms_per_update", "ms/update", "{:.2f}"),
    ("updates_per_s", "updates/s", "{:.0f}"),
    ("particles", "particles", "{}"),
    ("cue", "cue", "{}"),
)


def markdown_table(results: Seq[RunResult]) -> str:
    """One row per (sequence, tracker)."""
    lines = ["| " + " | ".join(h for _, h, _ in COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in results:
        row = r.summary()
        lines.append("| " + " | ".join(f.format(row[k]) for k, _, f in COLUMNS) + " |")
    return "\n".join(lines) + "\n"


def write_json(results: Seq[RunResult], path: Path) -> None:
    """The summaries (no per-frame lists) as a JSON list."""
    path.write_text(json.dumps([r.summary() for r in results], indent=2) + "\n")


def _sequence_plots(seq: Sequence, runs: Seq[RunResult], folder: Path) -> list[str]:
    vis = visible(seq.truth)
    frames = np.arange(len(seq.truth), dtype=np.float64)
    err, succ, prec = [], [], []
    for r in runs:
        pred = boxes_array(r.boxes)
        e = centre_errors(pred, seq.truth)
        err.append(Series(r.tracker, frames, e))
        succ.append(
            Series(r.tracker, SUCCESS_THRESHOLDS, success_curve(ious(pred[vis], seq.truth[vis])))
        )
        prec.append(Series(r.tracker, PRECISION_THRESHOLDS_PX, precision_curve(e[vis])))
    finite = np.concatenate([s.y[np.isfinite(s.y)] for s in err]) if err else np.zeros(1)
    top = float(min(max(np.percentile(finite, 98) if finite.size else 1.0, 25.0), 400.0))
    plots = {
        "centre_error": line_plot(err, f"{seq.name}: centre error", "frame", "px", (0.0, top)),
        "success": line_plot(
            succ, f"{seq.name}: success plot", "IoU threshold", "rate", (0.0, 1.0)
        ),
        "precision": line_plot(
            prec, f"{seq.name}: precision plot", "centre error threshold px", "rate", (0.0, 1.0)
        ),
    }
    names = []
    for kind, img in plots.items():
        name = f"{_safe(seq.name)}_{kind}.png"
        cv2.imwrite(str(folder / name), img)
        names.append(name)
    return names


def _likelihood_figure(
    seq: Sequence, first: npt.NDArray[np.uint8], folder: Path, tracker: AdaptiveTracker
) -> str:
    start = int(np.argmax(visible(seq.truth)))
    box = tuple(float(v) for v in seq.truth[start])
    tracker.init(first, (box[0], box[1], box[2], box[3]))
    images = [(feature_name(f), lik) for f, lik in tracker.likelihood_images(first)]
    name = f"{_safe(seq.name)}_likelihood.png"
    cv2.imwrite(
        str(folder / name), likelihood_panel(first, (box[0], box[1], box[2], box[3]), images)
    )
    return name


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def write_report(
    folder: Path,
    sequences: Seq[tuple[Sequence, npt.NDArray[np.uint8]]],
    results: Seq[RunResult],
    command: str,
    adaptive: AdaptiveTracker,
) -> Path:
    """Write ``report.md``, ``results.json`` and the PNGs into ``folder``; return report.md."""
    folder.mkdir(parents=True, exist_ok=True)
    parts = [
        "# Tracker evaluation\n",
        f"Command: `{command}`\n",
        "Frames with no box count as misses for precision and success (IoU 0); centre "
        "errors average only frames with a box. Timing excludes image decoding.\n",
        markdown_table(results),
    ]
    for seq, first_frame in sequences:
        runs = [r for r in results if r.sequence == seq.name]
        parts.append(f"\n## {seq.name}\n")
        for name in _sequence_plots(seq, runs, folder):
            parts.append(f"![{name}]({name})\n")
        lik = _likelihood_figure(seq, first_frame, folder, adaptive)
        parts.append(
            f"\nFirst frame and the likelihood images of the top features "
            f"(log-likelihood ratio back-projected):\n\n![{lik}]({lik})\n"
        )
    write_json(results, folder / "results.json")
    report = folder / "report.md"
    report.write_text("\n".join(parts))
    return report
