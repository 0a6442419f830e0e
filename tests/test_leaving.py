"""A plate leaving the image across its edge ends its track once less than
``LEFT_VIEW_SHARE`` of it is in view (real-imagery world seed 1: the plate left at the
bottom edge while its tracker's box stayed 98 px tall over the last 10-1 px of it, then
followed the background; issue 25's "no track on a wrong place for more than 10 frames")."""

from __future__ import annotations

import cv2
import numpy as np

from companion.corners import LEFT_VIEW_SHARE, Corners
from companion.perception_types import PerceptionConfig, Start, Track
from companion.tracks import TrackSet
from tests.plates import textured_plate
from tracker.acquire import project_corners
from tracker.adaptive import AdaptiveTracker
from tracker.boxes import in_view_share
from tracker.camera import CameraModel


def leaving(top_px: float) -> tuple[TrackSet, np.ndarray, float]:
    """A textured 120x80 plate on a textured wall, its top edge at ``top_px`` (rows below
    480 out of the image); its track's homography on it, its tracker's box on the part
    in view.  The track set, the frame and the plate's share in view."""
    grey, matcher, ref = textured_plate(7)
    rng = np.random.default_rng(8)
    wall = cv2.resize(rng.integers(60, 200, (48, 64)).astype(np.uint8), (640, 680),
                      interpolation=cv2.INTER_NEAREST)
    top = int(top_px)
    wall[top:top + 80, 300:420] = grey
    image = np.ascontiguousarray(cv2.merge([wall, wall, wall])[:480])
    sx, sy = 120 / ref.size_px[0], 80 / ref.size_px[1]
    hom = np.array([[sx, 0.0, 300.0], [0.0, sy, float(top)], [0.0, 0.0, 1.0]])
    box = (300.0, float(top), 120.0, float(min(80, 480 - top)))
    tracker = AdaptiveTracker()
    tracker.init(image, box)
    config = PerceptionConfig(parallel_tracks=False)
    ts = TrackSet(config, Corners(CameraModel(), config, {"plate": ref}, matcher))
    track = Track("plate", tracker, box, hom, corners=project_corners(ref, hom))
    ts.hand_over([Start(track, {"event": "acquired", "landmark": "plate"})])
    ts.adopt()
    share = in_view_share(project_corners(ref, hom), 640, 480)
    return ts, image, share


def test_a_plate_nearly_out_of_the_image_ends_its_track() -> None:
    ts, image, share = leaving(474.0)  # 6 of its 80 rows in view
    assert share < LEFT_VIEW_SHARE
    events = ts.update(image)
    assert {"event": "lost", "landmark": "plate"} in events
    assert "plate" not in ts.live


def test_a_plate_a_third_in_view_keeps_its_track() -> None:
    ts, image, share = leaving(454.0)  # 26 of 80 rows
    assert share > LEFT_VIEW_SHARE
    assert ts.update(image) == []
    assert "plate" in ts.live
