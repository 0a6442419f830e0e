"""Pure vision and geometry: adaptive landmark tracker, baselines, camera geometry.

Stable API::

    from tracker import AdaptiveTracker
    t = AdaptiveTracker(config=None, seed=0)
    t.init(image_bgr, (x, y, w, h))
    r = t.update(image_bgr)  # r.box (None when lost), r.confidence, r.features
"""

from tracker.adaptive import AdaptiveTracker
from tracker.baselines import CsrtTracker, MeanShiftTracker, MilTracker, ParticleFilterTracker
from tracker.config import TrackerConfig
from tracker.types import Box, TrackResult

__all__ = [
    "AdaptiveTracker",
    "Box",
    "CsrtTracker",
    "MeanShiftTracker",
    "MilTracker",
    "ParticleFilterTracker",
    "TrackResult",
    "TrackerConfig",
]
