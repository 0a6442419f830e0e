"""Between the particle tracker's frames a whole plate is followed by its corners'
alignment alone (``perception.track_every_frames``, issue 23): the same corners and fixes,
a third of the tracker's updates."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from companion.perception_types import PerceptionConfig
from tests.test_perception import flight
from tracker.adaptive import AdaptiveTracker


def _run(every: int, monkeypatch: pytest.MonkeyPatch) -> tuple[list[Any], int]:
    updates = 0
    update = AdaptiveTracker.update

    def counted(self: AdaptiveTracker, image: Any) -> Any:
        nonlocal updates
        updates += 1
        return update(self, image)

    with monkeypatch.context() as m:
        m.setattr(AdaptiveTracker, "update", counted)
        config = PerceptionConfig(track_every_frames=every, parallel_tracks=False)
        _, _, out = flight("survey", range(180, 216), config=config)
    return out, updates


def test_coasting_keeps_the_corners_and_runs_a_third_of_the_updates(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    every_frame, updates_1 = _run(1, monkeypatch)
    coasting, updates_3 = _run(3, monkeypatch)
    tracked = 0
    for (a, _, _), (b, _, _) in zip(every_frame, coasting, strict=True):
        corners_a = {t.landmark_id: t.corners for t in a.tracks}
        corners_b = {t.landmark_id: t.corners for t in b.tracks}
        assert corners_a.keys() == corners_b.keys()
        for lid, ca in corners_a.items():
            cb = corners_b[lid]
            assert (ca is None) == (cb is None)
            if ca is not None and cb is not None:
                np.testing.assert_array_equal(ca, cb)
                tracked += 1
        assert type(a.fix) is type(b.fix)
    assert tracked >= 30  # plates were followed: the comparison proves something
    assert updates_1 >= tracked and updates_3 <= 0.45 * updates_1
    # the tracker's box stays on the plate it did not look at
    for result, _, _ in coasting:
        for t in result.tracks:
            if t.corners is not None:
                x, y, w, h = t.box
                cx, cy = np.mean(t.corners, axis=0)
                assert abs(x + w / 2 - cx) < 0.25 * w and abs(y + h / 2 - cy) < 0.25 * h
