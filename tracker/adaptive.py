"""The adaptive landmark tracker: online feature selection + mean-shift-embedded particle filter.

:class:`AdaptiveTracker` holds one target's :class:`tracker.step.TrackState`, its
configuration and its random generator, and calls :func:`tracker.step.step` once per frame;
the method (the paper's loop, where each part lives) is in :mod:`tracker.step`.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from tracker.config import TrackerConfig, check_config
from tracker.step import TrackState, coast, start, step
from tracker.target_model import planes_of
from tracker.types import Box, Cue, TrackResult
from tracker.validation import check_box, check_image, check_same_frame

FloatArray = npt.NDArray[np.float64]


class AdaptiveTracker:
    """Track one target; ``init`` on the first frame, then ``update`` on each next frame."""

    name = "adaptive"

    def __init__(self, config: TrackerConfig | None = None, seed: int = 0) -> None:
        self.config = config if config is not None else TrackerConfig()
        check_config(self.config)
        self.rng = np.random.default_rng(seed)
        self._state: TrackState | None = None

    def init(self, image_bgr: npt.NDArray[np.uint8], box: Box, rank_phase: int = 0) -> None:
        """Start tracking the target inside ``box`` = (x, y, w, h) of the first frame.

        ``rank_phase`` shifts the periodic re-ranking by that many frames: trackers started
        together with different phases do not all re-rank on the same frame (a caller
        tracking several targets in real time keeps its per-frame cost even).
        """
        image = check_image(image_bgr)
        self._state = start(image, check_box(box, image.shape), self.config, rank_phase)

    @property
    def state(self) -> TrackState:
        """The state after the last ``init`` or ``update`` (immutable)."""
        if self._state is None:
            raise ValueError("state: call init(image_bgr, box) first")
        return self._state

    @property
    def features(self) -> tuple[int, ...]:
        """Ids of the features in use (best first)."""
        return self.state.model.features

    @property
    def particle_centres(self) -> FloatArray:
        """(N, 2) image positions (x, y) of the particle set after the last update."""
        return np.asarray(self.state.particles[:, :2], dtype=np.float64).copy()

    @property
    def cue(self) -> Cue:
        """``"colour"`` or ``"grayscale"`` (the grey features and the template, no colour)."""
        return self.state.first.cue

    def update(self, image_bgr: npt.NDArray[np.uint8]) -> TrackResult:
        """Track into the next frame; ``box`` is None while the target is lost."""
        if self._state is None:
            raise ValueError("update: call init(image_bgr, box) first")
        check_same_frame(image_bgr, self._state.shape)
        self._state, result = step(self._state, image_bgr, self.config, self.rng)
        return result

    def coast(self, shift: tuple[float, float], ratio: float = 1.0) -> Box:
        """Skip a frame: the target moved by ``shift`` (x, y pixels) and its size by
        ``ratio``, as the caller found without this tracker; returns the box moved."""
        if self._state is None:
            raise ValueError("coast: call init(image_bgr, box) first")
        self._state, box = coast(self._state, shift, ratio, self.config)
        return box

    def likelihood_images(
        self, image_bgr: npt.NDArray[np.uint8]
    ) -> list[tuple[int, npt.NDArray[np.float32]]]:
        """The log-likelihood ratio of each selected feature back-projected on a whole frame.

        For reports and inspection only (fig. 5); tracking never computes whole-frame features.
        """
        model = self.state.model
        planes = planes_of(check_image(image_bgr), model.features, self.config)
        return [
            (fid, model.llr[i][planes[i]].astype(np.float32))
            for i, fid in enumerate(model.features)
        ]
