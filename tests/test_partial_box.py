"""A plate that comes into view across the image's edge (issue 19's square, its corners):
its tracker's box was seated on the part in view, so the outline found is checked against
the outline it started from, not centred on that box, and once the plate is whole the
tracker is started again on it (``Track.partial_box``, ``Corners._seat``).  And an outline
run out far beyond the image gives no corners, instead of a frame the pose solver refuses."""

from __future__ import annotations

import numpy as np

from companion.corner_noise import CornerNoise
from companion.perception_types import PerceptionConfig, Track
from tests.test_perception import flight
from tracker.adaptive import AdaptiveTracker
from tracker.camera import CameraModel
from tracker.pose.config import PoseConfig
from tracker.pose.types import PoseFix


def test_a_plate_coming_into_view_keeps_its_corners_and_its_tracker_is_reseated() -> None:
    _, _, out = flight("survey", range(0, 112))
    # frames 84-90: wall-01 two thirds in view from the left; its tracker's box (the part
    # that was in view when it was acquired) sits 50 px right of the plate's centre
    for result, truth, state in out[84:91]:
        box = {b.landmark_id: b for b in truth.boxes}["wall-01"]
        assert 0.6 < box.in_view_frac < 0.8
        track = {t.landmark_id: t for t in result.tracks}["wall-01"]
        assert track.corners is not None, result.frame_index
        assert isinstance(result.fix, PoseFix), (result.frame_index, result.no_fix_reason)
        error = np.linalg.norm(np.subtract(result.fix.position_ned_m, state.position_ned_m))
        assert error < 0.05, (result.frame_index, error)
    # whole since frame 105: the tracker's box is the plate's
    for result, _, _ in out[106:112]:
        track = {t.landmark_id: t for t in result.tracks}["wall-01"]
        assert track.corners is not None
        x, y, w, h = track.box
        (x0, y0), (x1, y1) = track.corners.min(axis=0), track.corners.max(axis=0)
        assert abs(x + w / 2 - (x0 + x1) / 2) < 4 and abs(y + h / 2 - (y0 + y1) / 2) < 4
        assert abs(w - (x1 - x0)) < 0.1 * (x1 - x0), (result.frame_index, track.box)


def _cut(corners: list[tuple[float, float]]
         ) -> tuple[tuple[bool, bool, bool, bool] | None, float] | None:
    noise = CornerNoise(CameraModel(), PerceptionConfig(), PoseConfig(), None, [])
    track = Track("p", AdaptiveTracker(), (0.0, 400.0, 100.0, 80.0), None,
                  corners=np.array(corners, np.float64))
    return noise.cut(track)


def test_an_outline_run_out_beyond_one_image_size_gives_no_corners() -> None:
    # a plate cut by the bottom edge, its two lower corners extrapolated
    near = [(100.0, 420.0), (300.0, 420.0), (310.0, 560.0), (90.0, 560.0)]
    cut = _cut(near)
    assert cut is not None
    measured, grow = cut
    assert measured == (True, True, False, False) and grow > 1.0
    # the same plate seen nearly edge-on: its lower corners tens of thousands of px out
    far = [(100.0, 420.0), (300.0, 420.0), (52000.0, 48000.0), (-50000.0, 48000.0)]
    assert _cut(far) is None
