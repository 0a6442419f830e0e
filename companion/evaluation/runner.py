"""Run trackers over sequences, timing each ``update`` (image decoding excluded)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt

from companion.errors import InputError
from companion.evaluation.metrics import Scores, score, visible
from companion.evaluation.sequences import Sequence
from tracker import (
    AdaptiveTracker,
    CsrtTracker,
    MeanShiftTracker,
    MilTracker,
    ParticleFilterTracker,
    TrackerConfig,
)
from tracker.types import Box, Tracker, TrackResult

TRACKERS: dict[str, Callable[[int, TrackerConfig | None], Tracker]] = {
    "adaptive": lambda seed, config: AdaptiveTracker(config=config, seed=seed),
    "pf": lambda seed, _: ParticleFilterTracker(seed=seed),
    "meanshift": lambda seed, _: MeanShiftTracker(seed=seed),
    "mil": lambda seed, _: MilTracker(seed=seed),
    "csrt": lambda seed, _: CsrtTracker(seed=seed),
}


@dataclass(frozen=True)
class RunResult:
    """One tracker on one sequence: scores, speed and the raw per-frame output."""

    sequence: str
    tracker: str
    scores: Scores
    median_ms_per_update: float
    updates_per_s: float
    particles: int
    cue: str
    boxes: tuple[Box | None, ...]
    confidences: tuple[float, ...]

    def summary(self) -> dict[str, object]:
        """JSON-ready summary without the per-frame lists."""
        out: dict[str, object] = {"sequence": self.sequence, "tracker": self.tracker}
        out.update(asdict(self.scores))
        out.update(
            median_ms_per_update=self.median_ms_per_update,
            updates_per_s=self.updates_per_s,
            particles=self.particles,
            cue=self.cue,
        )
        return out


def make_tracker(name: str, seed: int = 0, config: TrackerConfig | None = None) -> Tracker:
    """A tracker by its name in :data:`TRACKERS` (``config`` is used by ``adaptive``)."""
    if name not in TRACKERS:
        raise InputError(f"unknown tracker {name!r}; expected one of {', '.join(TRACKERS)}")
    try:
        return TRACKERS[name](seed, config)
    except ValueError as err:  # e.g. csrt without opencv-contrib: one clear line
        raise InputError(str(err)) from err


def run_frames(
    tracker: Tracker,
    name: str,
    sequence: Sequence,
    images: list[npt.NDArray[np.uint8]],
    progress: Callable[[], None] | None = None,
) -> RunResult:
    """Init on the first frame with truth, then update on every later frame."""
    vis = visible(sequence.truth)
    if not vis.any():
        raise InputError(f"{sequence.name}: no frame has a truth box")
    start = int(np.argmax(vis))
    first = sequence.truth[start]
    tracker.init(images[start], (first[0], first[1], first[2], first[3]))
    boxes: list[Box | None] = [(first[0], first[1], first[2], first[3])]
    conf = [1.0]
    times: list[float] = []
    last: TrackResult | None = None
    for image in images[start + 1 :]:
        t0 = time.perf_counter()
        last = tracker.update(image)
        times.append(time.perf_counter() - t0)
        boxes.append(last.box)
        conf.append(last.confidence)
        if progress is not None:
            progress()
    ms = float(np.median(times) * 1e3) if times else float("nan")
    return RunResult(
        sequence=sequence.name,
        tracker=name,
        scores=score(boxes[1:], sequence.truth[start + 1 :]),
        median_ms_per_update=ms,
        updates_per_s=1e3 / ms if ms > 0 else float("inf"),
        particles=last.particles if last is not None else 0,
        cue=last.cue if last is not None else "colour",
        boxes=tuple([None] * start + boxes),
        confidences=tuple([0.0] * start + conf),
    )
