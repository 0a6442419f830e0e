"""The track set's hand-over between the two threads, the frozen track views a result
carries, and the monitoring JSON built from them (docs/monitoring.md)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from companion.corners import Corners
from companion.perception_types import PerceptionConfig, Start, Track, TrackView
from companion.reporting import pose_json, track_json
from companion.tracks import TrackSet
from tracker.acquire import ReferenceMatcher
from tracker.camera import CameraModel
from tracker.pose.types import PoseFix


def trackset(max_tracks: int = 8) -> TrackSet:
    config = PerceptionConfig(max_tracks=max_tracks, parallel_tracks=False)
    corners = Corners(CameraModel(), config, {}, ReferenceMatcher())
    return TrackSet(config, corners)


def track(lid: str) -> Track:
    return Track(lid, None, (10.0, 20.0, 30.0, 40.0), None)  # type: ignore[arg-type]


def start(lid: str) -> Start:
    return Start(track(lid), {"event": "acquired", "landmark": lid})


def test_housekeeping_sees_a_snapshot_and_hands_over_under_the_lock() -> None:
    """What housekeeping is given does not change under it; what it hands over is taken
    by the next adoption, each with its event, a landmark already tracked dropped."""
    ts = trackset()
    ts.hand_over([start("a")])
    seen = ts.snapshot()
    assert seen.tracked == frozenset() and seen.waiting == ("a",) and seen.busy() == 1
    assert ts.adopt() == [{"event": "acquired", "landmark": "a"}]
    assert seen.waiting == ("a",) and seen.tracked == frozenset()  # a snapshot: unchanged
    now = ts.snapshot()
    assert now.tracked == {"a"} and now.waiting == () and now.taken("a")
    ts.hand_over([start("a"), start("b")])  # "a" again: dropped, without its event
    assert ts.adopt() == [{"event": "acquired", "landmark": "b"}]
    assert set(ts.live) == {"a", "b"} and ts.adopt() == []


def test_adoption_stops_at_max_tracks() -> None:
    ts = trackset(max_tracks=2)
    ts.hand_over([start("a"), start("b"), start("c")])
    assert [e["landmark"] for e in ts.adopt()] == ["a", "b"]
    assert set(ts.live) == {"a", "b"}


def test_a_result_keeps_the_track_of_its_frame() -> None:
    """The view is a copy: the next frame's update of the track does not reach it."""
    t = track("a")
    t.corners = np.array([[1.0, 2.0], [3.0, 2.0], [3.0, 4.0], [1.0, 4.0]])
    t.features = (5, 2)
    view = TrackView.of(t)
    t.corners[0, 0] = 99.0
    t.box, t.confidence, t.corners = (0.0, 0.0, 1.0, 1.0), 0.1, None
    assert view.box == (10.0, 20.0, 30.0, 40.0) and view.confidence == 1.0
    assert view.corners is not None and view.corners[0, 0] == 1.0
    with pytest.raises(ValueError):
        view.corners[0, 0] = 7.0  # read-only
    with pytest.raises(AttributeError):
        view.box = (1.0, 1.0, 1.0, 1.0)  # type: ignore[misc]


def test_the_monitoring_json_of_a_track_and_a_fix() -> None:
    """The payloads of docs/monitoring.md, rounded as they always were (corners in the
    alignment's own dtype: float32 corners round as float32)."""
    corners = np.array([[10.123, 20.456], [30.0, 20.0], [30.0, 40.0], [10.0, 40.0]],
                       np.float32)
    view = TrackView("sign-01", (10.04, 20.06, 20.0, 20.0), 0.87654, (12, 3), corners)
    assert track_json(view) == {
        "landmark_id": "sign-01", "box": [10.0, 20.1, 20.0, 20.0], "confidence": 0.877,
        "features": [12, 3], "corners": np.round(corners, 2).tolist()}
    assert track_json(view)["corners"][0][0] == float(np.float32(10.12))
    assert track_json(TrackView("b", (1.0, 2.0, 3.0, 4.0), 0.5, (), None))["corners"] is None
    cov = np.diag([0.01, 0.02, 0.03, 1e-4, 2e-4, 3.33333e-4])
    fix = PoseFix(5, (1.23456, -2.0, -30.00004), (0.1, 0.2, 3.123456), cov, 80, ("a", "b"),
                  "bearing_ls", attitude_prior="used")
    assert json.dumps(pose_json(fix)) == (
        '{"position_ned_m": [1.2346, -2.0, -30.0], "attitude_rpy_rad": [0.1, 0.2, 3.12346], '
        '"covariance_diag": [0.01, 0.02, 0.03, 0.0001, 0.0002, 0.000333333], "quality": 80, '
        '"landmark_ids": ["a", "b"], "solver": "bearing_ls", "attitude_prior": "used"}')
    sent = dataclasses.replace(fix, sent_position_ned_m=(1.0, -2.0, -30.0))
    assert pose_json(sent)["sent_position_ned_m"] == [1.0, -2.0, -30.0]  # what went out
