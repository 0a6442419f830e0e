"""Observers that keep the truth beside a flight's results (never in them).

A flight whose source knows where the vehicle truly was (a simulated camera, a follow-mode
camera, a recording with ``truth_pose.csv``) subscribes one of these to the results
(:class:`companion.app.ResultObserver`):

* :class:`TruthTags`: each ``pose`` report of a fix also carries the true position the
  frame showed (``truth_position_ned_m``) and the fix's distance from it
  (``truth_error_m``) -- added to the report through the observer's ``pose_fields``, the
  frozen result is left as it is;
* :class:`FixTruths`: the same, and every fix kept with its truth and the mean distance to
  the landmarks it used, for a summary's RMSE and NEES (``companion demo``, ``replay``).

Nothing here knows the simulator: the truth comes as a function of the frame
(:class:`companion.sources.base.KnowsTruth` says a source offers one).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from companion.app import Frame, FrameResult, ResultObserver
from tracker.pose.types import MapLandmark, PoseFix

#: The true position (flight NED, m) of the vehicle when a frame (the pipeline's, a
#: :class:`companion.sources.base.Frame`) was taken, or None.
TruthOf = Callable[[Any], Sequence[float] | None]
#: A fix, the true position of its frame (flight NED, m) and its mean landmark distance (m).
FixTruth = tuple[PoseFix, tuple[float, float, float], float]


class TruthTags(ResultObserver):
    """Adds the truth to the pose report of every fix whose frame's truth is known."""

    def __init__(self, truth_of: TruthOf) -> None:
        self.truth_of = truth_of
        self._tags: tuple[int, dict[str, Any]] | None = None  # (frame index, fields)

    def on_result(self, frame: Frame, result: FrameResult) -> None:
        self._tags = None
        if result.fix is None:
            return
        seen = self.truth_of(frame)
        if seen is None:
            return
        truth = (float(seen[0]), float(seen[1]), float(seen[2]))
        self._tags = (result.frame_index, {
            "truth_position_ned_m": [round(v, 4) for v in truth],
            "truth_error_m": round(math.dist(result.fix.position_ned_m, truth), 4)})
        self.fix_with_truth(result.fix, truth)

    def fix_with_truth(self, fix: PoseFix, truth: tuple[float, float, float]) -> None:
        """A fix whose frame's truth is known (for subclasses that keep it)."""

    def pose_fields(self, result: FrameResult) -> dict[str, Any]:
        tags = self._tags
        return dict(tags[1]) if tags is not None and tags[0] == result.frame_index else {}


class FixTruths(TruthTags):
    """:class:`TruthTags` that also keeps every fix with its truth (:attr:`fixes`)."""

    def __init__(self, truth_of: TruthOf, landmarks: Sequence[MapLandmark]) -> None:
        super().__init__(truth_of)
        self.landmarks: Mapping[str, MapLandmark] = {lm.landmark_id: lm for lm in landmarks}
        self.fixes: list[FixTruth] = []

    def fix_with_truth(self, fix: PoseFix, truth: tuple[float, float, float]) -> None:
        used = [self.landmarks[i] for i in fix.landmark_ids if i in self.landmarks]
        dist = float(np.mean([math.dist(truth, lm.position_ned_m) for lm in used])) \
            if used else float("nan")
        self.fixes.append((fix, truth, dist))
