"""Per-target update speed on 640x480 frames, one core, image decoding excluded.

    PYTHONPATH=. python benchmarks/tracker_speed.py [--data ../shared/data/otb] [--repeats 5]

Frames: the first 150 of OTB Coke (640x480) when present, else the simulated illumination
sequence (640x480).  Each tracker runs ``--repeats`` times over the same decoded frames; the
script prints the median ms per update of every run, their minimum (the run least disturbed by
other processes on a shared machine) and median, and the ratio to TrackerMIL and (where
opencv-contrib is installed) TrackerCSRT measured in the same run.  ``--clock thread`` times
each update by ``time.thread_time`` (the CPU time of the one thread that runs it, cv2 on one
thread) instead of the wall clock, so another process's load does not count: the figure to
compare two versions on a shared machine.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from companion.evaluation.runner import make_tracker, run_frames  # noqa: E402
from companion.evaluation.sequences import Sequence, load_sequence  # noqa: E402
from companion.evaluation.synthetic import SynthSpec, generate  # noqa: E402
from tracker.baselines import csrt_available  # noqa: E402


def _frames(data: Path) -> tuple[Sequence, list[np.ndarray]]:
    if (data / "Coke").is_dir():
        seq = load_sequence(data / "Coke")
        seq = Sequence(seq.name, seq.frames[:150], seq.truth[:150])
        return seq, list(seq.images())
    frames, truth = generate(SynthSpec(frames=150))
    return Sequence("illumination", (), truth), frames


def _cpu_median_ms(name: str, seed: int, seq: Sequence, frames: list[np.ndarray]) -> float:
    """Median CPU time (``time.thread_time``) per update, ms: init on the first frame's truth,
    then every later frame."""
    tracker = make_tracker(name, seed)
    x, y, w, h = (float(v) for v in seq.truth[0])
    tracker.init(frames[0], (x, y, w, h))
    times = []
    for image in frames[1:]:
        t0 = time.thread_time()
        tracker.update(image)
        times.append(time.thread_time() - t0)
    return float(np.median(times) * 1e3)


def main() -> int:
    root = Path(__file__).resolve().parents[1]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    shared = Path(os.environ.get("LMC_SHARED_DATA", root / "../shared/data"))
    parser.add_argument("--data", type=Path, default=shared / "otb")
    parser.add_argument("--repeats", type=int, default=5)
    default = "adaptive,pf,meanshift,mil" + (",csrt" if csrt_available() else "")
    parser.add_argument("--trackers", default=default)
    parser.add_argument("--clock", choices=("wall", "thread"), default="wall")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    seq, frames = _frames(args.data)
    print(
        f"{seq.name}: {len(frames)} frames {frames[0].shape[1]}x{frames[0].shape[0]}, "
        f"cv2 threads {cv2.getNumThreads()}, clock {args.clock}, "
        f"load avg {os.getloadavg()[0]:.1f}"
    )
    best: dict[str, float] = {}
    for name in args.trackers.split(","):
        runs = [
            _cpu_median_ms(name, seed, seq, frames)
            if args.clock == "thread"
            else run_frames(make_tracker(name, seed), name, seq, frames).median_ms_per_update
            for seed in range(args.repeats)
        ]
        best[name] = min(runs)
        print(
            f"{name:10s} median ms/update per run: "
            + " ".join(f"{v:.2f}" for v in runs)
            + f" | min {min(runs):.2f} ms = {1e3 / min(runs):.0f} updates/s"
            + f" | median {np.median(runs):.2f} ms = {1e3 / np.median(runs):.0f} updates/s",
            flush=True,
        )
    for peer in ("mil", "csrt"):
        if "adaptive" in best and peer in best:
            print(
                f"adaptive is {best[peer] / best['adaptive']:.1f}x faster than {peer} "
                f"(min of run medians)"
            )
    print(f"load avg after: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
