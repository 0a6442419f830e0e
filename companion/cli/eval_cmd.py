"""``companion eval``: tracker accuracy and speed against baselines, with a report and plots."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import cv2

from companion.errors import InputError
from companion.evaluation.report import markdown_table, write_json, write_report
from companion.evaluation.runner import TRACKERS, RunResult, make_tracker, run_frames
from companion.evaluation.sequences import load_sequence
from companion.settings import Settings
from tracker import AdaptiveTracker


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion eval``."""
    parser = sub.add_parser(
        "eval",
        help="measure tracker accuracy and speed against baselines",
        description="Run trackers over OTB folders (img/, groundtruth_rect.txt) or recorded "
        "streams with truth_boxes.csv and print, per sequence and tracker: mean and median "
        "centre error, precision at 20 px, success AUC, frames lost, median ms per update, "
        "updates/s and particle count. The adaptive tracker uses the [tracker] settings.",
    )
    parser.add_argument(
        "sequences",
        nargs="+",
        type=Path,
        metavar="SEQ_DIR",
        help="OTB sequence folder or recorded stream folder",
    )
    parser.add_argument(
        "--trackers",
        default="adaptive,pf,meanshift,mil",
        metavar="LIST",
        help=f"comma-separated, from {','.join(TRACKERS)} (default: all)",
    )
    parser.add_argument("--json", type=Path, metavar="FILE", help="write the results as JSON")
    parser.add_argument(
        "--report",
        type=Path,
        metavar="DIR",
        help="write report.md with a table and PNG plots into DIR",
    )
    parser.add_argument(
        "--landmark",
        metavar="ID",
        help="landmark id to follow in recorded streams (default: the first in truth_boxes.csv)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="N",
        help="random seed of the particle trackers (default 0)",
    )
    parser.set_defaults(handler=run)


class _Progress:
    """A one-line progress bar on a terminal (stderr); silent otherwise."""

    def __init__(self, total: int) -> None:
        self.total, self.done = max(total, 1), 0
        self.live = sys.stderr.isatty()
        self.label = ""

    def step(self) -> None:
        self.done += 1
        if self.live and (self.done % 5 == 0 or self.done == self.total):
            filled = round(30 * self.done / self.total)
            sys.stderr.write(
                f"\r[{'#' * filled}{'.' * (30 - filled)}] "
                f"{100 * self.done // self.total:3d}% {self.label:<30}"
            )
            sys.stderr.flush()

    def close(self) -> None:
        if self.live:
            sys.stderr.write("\n")


def _tracker_names(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in TRACKERS]
    if unknown or not names:
        raise InputError(f"--trackers: expected names from {','.join(TRACKERS)}, got {text!r}")
    return names


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Evaluate; print the markdown table; optionally write JSON and the report."""
    names = _tracker_names(args.trackers)
    cv2.setNumThreads(1)  # per-target speed on one core, as the benchmarks report it
    sequences = [load_sequence(folder, args.landmark) for folder in args.sequences]
    progress = _Progress(sum(len(s.frames) - 1 for s in sequences) * len(names))
    results: list[RunResult] = []
    firsts = []
    for seq in sequences:
        images = list(seq.images())  # decoded up front: timing excludes decoding
        firsts.append((seq, images[0]))
        for name in names:
            progress.label = f"{seq.name} {name}"
            tracker = make_tracker(name, args.seed, settings.tracker)
            results.append(run_frames(tracker, name, seq, images, progress.step))
    progress.close()
    sys.stdout.write(markdown_table(results))
    if args.json is not None:
        write_json(results, args.json)
    if args.report is not None:
        command = "companion eval " + shlex.join(sys.argv[2:] if len(sys.argv) > 2 else [])
        report = write_report(
            args.report, firsts, results, command, AdaptiveTracker(settings.tracker, args.seed)
        )
        sys.stdout.write(f"report: {report}\n")
    return 0
