"""Tracker benchmark: accuracy and speed of adaptive vs pf, meanshift and MIL.

    PYTHONPATH=. python benchmarks/tracker_otb.py [--data ../shared/data/otb] [--seeds 0,1,2]
        [--ablation] [--trackers adaptive,pf] [--set template_update_score=0.5 ...]

Runs on one core (OMP/OpenBLAS/MKL threads = 1, cv2.setNumThreads(1)); image decoding is
excluded from timing.  Sequences: Coke, Tiger1, Car4, Crossing, boat1 (when present) and the
simulated illumination-change sequence (written to a temporary OTB folder and read back like
the others).  Prints a markdown table (mean over seeds for the particle trackers; one run of
the OpenCV peers MIL and, where opencv-contrib is installed, CSRT) with updates/s measured in
the same run.  ``--ablation`` adds the adaptive tracker with all particles mean-shifted
(Shan et al.) and with none.  ``--trackers`` runs only the named rows (exploring: our tracker
alone, CSRT once for the table); ``--set NAME=VALUE`` overrides a ``TrackerConfig`` field,
named bare (``particles``, not ``filter.particles``), of every adaptive row (a candidate
measured on all sequences before it becomes a default);
``--per-seed`` adds each seed's AUC and mean centre error; ``--dump DIR`` writes, per
sequence, tracker and seed, a CSV of every frame's box, truth, confidence and centre error
(``DIR/<sequence>-<tracker>-s<seed>.csv``) to find the frames that carry a mean.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from companion.evaluation.metrics import centre_errors  # noqa: E402
from companion.evaluation.runner import RunResult, make_tracker, run_frames  # noqa: E402
from companion.evaluation.sequences import load_sequence  # noqa: E402
from companion.evaluation.synthetic import SynthSpec, write_otb  # noqa: E402
from tracker import AdaptiveTracker, TrackerConfig  # noqa: E402
from tracker.baselines import csrt_available  # noqa: E402
from tracker.config import GROUP_OF, check_config, replace  # noqa: E402

SEQUENCES = ("Coke", "Tiger1", "Car4", "Crossing", "boat1")
PEERS = ("mil", "csrt")  # OpenCV peers: one run (the seed only seeds cv2.setRNGSeed)


def _override(sets: list[str]) -> TrackerConfig:
    """``TrackerConfig`` with ``NAME=VALUE`` fields replaced (``NAME`` a field's bare name,
    e.g. ``particles`` for ``filter.particles``; the value parsed as the field's type)."""
    base = TrackerConfig()
    changes: dict[str, object] = {}
    for item in sets:
        name, _, text = item.partition("=")
        if name not in GROUP_OF:
            raise SystemExit(f"--set {item}: TrackerConfig has no field {name!r}")
        old = getattr(getattr(base, GROUP_OF[name]), name)
        changes[name] = (
            text.lower() in ("1", "true", "yes") if isinstance(old, bool) else type(old)(text)
        )
    config = replace(base, **changes)
    check_config(config)
    return config


def _variants(ablation: bool, base: TrackerConfig) -> dict[str, TrackerConfig | None]:
    out: dict[str, TrackerConfig | None] = {
        "adaptive": base,
        "pf": None,
        "meanshift": None,
        "mil": None,
    }
    if csrt_available():  # opencv-contrib only: run from a separate venv (docs/benchmarks.md)
        out["csrt"] = None
    if ablation:
        out["adaptive-allshift"] = replace(base, mean_shift_fraction=1.0)
        out["adaptive-noshift"] = replace(base, mean_shift_fraction=0.0)
    return out


def _mean(runs: list, key: str) -> float:
    return float(np.mean([getattr(r.scores, key) for r in runs]))


def _dump(path: Path, run: RunResult, truth: np.ndarray) -> None:
    """One CSV row per frame: box (empty while lost), truth, confidence, centre error px."""
    path.parent.mkdir(parents=True, exist_ok=True)
    pred = np.array([b if b is not None else (np.nan,) * 4 for b in run.boxes], float)
    err = centre_errors(pred, truth)
    with path.open("w") as out:
        out.write("frame,x,y,w,h,tx,ty,tw,th,confidence,centre_err_px\n")
        for i, (box, gt, conf, e) in enumerate(zip(pred, truth, run.confidences, err, strict=True)):
            cells = [*box, *gt, conf, e]
            out.write(f"{i}," + ",".join(f"{c:.2f}" for c in cells) + "\n")


def main() -> int:
    root = Path(__file__).resolve().parents[1]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--data",
        type=Path,
        default=Path(os.environ.get("LMC_SHARED_DATA", root / "../shared/data")) / "otb",
    )
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--ablation", action="store_true")
    parser.add_argument("--only", default="", help="comma-separated sequence names")
    parser.add_argument("--trackers", default="", help="comma-separated rows (default: all)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--per-seed", action="store_true")
    parser.add_argument("--dump", type=Path, default=None, metavar="DIR")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    seeds = [int(s) for s in args.seeds.split(",")]
    tmp = Path(tempfile.mkdtemp(prefix="illum-"))
    folders = [args.data / s for s in SEQUENCES if (args.data / s).is_dir()]
    folders.append(tmp / "illumination")
    write_otb(SynthSpec(frames=200), tmp / "illumination")
    if args.only:
        folders = [f for f in folders if f.name in args.only.split(",")]
    print(
        "| sequence | tracker | AUC | AUC min-max | prec@20 | mean err px | err x / y px "
        "| lost | ms/update | updates/s | particles | cue |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for folder in folders:
        seq = load_sequence(folder)
        images = list(seq.images())
        size = f"{images[0].shape[1]}x{images[0].shape[0]}"
        variants = _variants(args.ablation, _override(args.set))
        for name, config in variants.items():
            if args.trackers and name not in args.trackers.split(","):
                continue
            runs = []
            for seed in seeds if name not in PEERS else seeds[:1]:
                tracker = (
                    AdaptiveTracker(config, seed)
                    if config is not None
                    else make_tracker(name, seed)
                )
                runs.append(run_frames(tracker, name, seq, images))
                if args.dump is not None:
                    _dump(args.dump / f"{seq.name}-{name}-s{seed}.csv", runs[-1], seq.truth)
            auc = [r.scores.success_auc for r in runs]
            ms = float(np.median([r.median_ms_per_update for r in runs]))
            print(
                f"| {seq.name} ({size}) | {name} | {np.mean(auc):.3f} | {min(auc):.3f}-"
                f"{max(auc):.3f} | {_mean(runs, 'precision_20px'):.3f} | "
                f"{_mean(runs, 'mean_centre_error_px'):.1f} | "
                f"{_mean(runs, 'mean_error_x_px'):.2f} / {_mean(runs, 'mean_error_y_px'):.2f} | "
                f"{max(r.scores.frames_lost for r in runs)} | "
                f"{ms:.2f} | {1e3 / ms:.0f} | {runs[0].particles} | {runs[0].cue} |",
                flush=True,
            )
            if args.per_seed and len(runs) > 1:
                print(
                    "|  | per seed | "
                    + " ".join(f"{a:.3f}" for a in auc)
                    + " | | "
                    + " ".join(f"{r.scores.mean_centre_error_px:.1f}" for r in runs)
                    + " | | | | | | |",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
