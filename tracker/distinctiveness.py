"""How well a landmark stands out from its surroundings: the best variance ratio.

The landmark database's distinctiveness score (paper sec. 2.1: "distinctive visual
characteristics") is measured with the tracker's own ranking (paper eq. 6-8): the 49
colour features are histogrammed inside the landmark's box and in a ring around it, and
the best feature's variance ratio is the score.  A landmark no feature can separate from
its background is a poor landmark for this tracker, whatever it looks like to a person.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from tracker.config import TrackerConfig
from tracker.features import colour_feature_bins, colour_weights
from tracker.ranking import masked_histograms, ring_masks, variance_ratio
from tracker.validation import check_box, check_image


def best_variance_ratio(
    image_bgr: npt.NDArray[np.uint8],
    box: tuple[float, float, float, float],
    config: TrackerConfig | None = None,
) -> float:
    """The highest variance ratio over the 49 colour features, box against its ring.

    Uses the tracker's bin count, ring size and floor (``config``), so a landmark scores
    exactly as the tracker will see it.  ValueError for a bad image or box.
    """
    cfg = (config or TrackerConfig()).features
    check_image(image_bgr, "image_bgr")
    x, y, w, h = check_box(box, image_bgr.shape, "box")
    ids = tuple(range(len(colour_weights())))
    bins = colour_feature_bins(image_bgr, ids, cfg.bins)
    inner, ring = ring_masks(image_bgr.shape[:2], (x, y, w, h), cfg.ring_area_ratio)
    if not ring.any():
        raise ValueError(
            "box: expected a box with some surroundings inside the image, "
            "got one that covers it all"
        )
    p = masked_histograms(bins, inner, cfg.bins)
    q = masked_histograms(bins, ring, cfg.bins)
    return float(variance_ratio(p, q, cfg.loglik_floor).max())
