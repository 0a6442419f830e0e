"""Value types shared by every tracker: the per-frame result and the tracker protocol."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
import numpy.typing as npt

Box = tuple[float, float, float, float]
"""An axis-aligned box ``(x, y, w, h)`` in pixels, (x, y) = top-left corner."""

Cue = Literal["colour", "grayscale"]


@dataclass(frozen=True)
class TrackResult:
    """What a tracker reports for one frame.

    ``box`` is ``None`` when the tracker considers the target lost (then ``lost`` is True).
    ``confidence`` is in [0, 1]; ``features`` are the ids of the features in use (see
    :func:`tracker.features.feature_name`); ``cue`` says whether colour features or the
    grayscale ones (intensity, gradient, contrast, orientation, LBP) were used; ``particles``
    is the number of
    particles evaluated for this frame (0 for trackers without particles).
    """

    box: Box | None
    confidence: float
    features: tuple[int, ...] = ()
    lost: bool = False
    cue: Cue = "colour"
    particles: int = 0


class Tracker(Protocol):
    """The interface every tracker here (adaptive, baselines, OpenCV wrapper) implements."""

    name: str

    def init(self, image_bgr: npt.NDArray[np.uint8], box: Box) -> None:
        """Start tracking the target inside ``box`` of the first frame."""
        ...

    def update(self, image_bgr: npt.NDArray[np.uint8]) -> TrackResult:
        """Track the target into the next frame."""
        ...
