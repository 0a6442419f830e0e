"""Between the particle tracker's frames a whole plate is followed by its corners'
alignment alone (``perception.track_every_frames``, issue 23): the same corners and fixes,
a third of the tracker's updates."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import companion.corners as corners_module
from companion.perception_types import PerceptionConfig
from tests.acquire.test_verify import scene
from tests.test_perception import flight
from tests.test_perception_checks import perception, track_at
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


def _one_track(config: PerceptionConfig, box: tuple[float, float, float, float]
               ) -> tuple[Any, Any, Any, list[int]]:
    """A perception of one plate (tests/acquire/test_verify.py's scene) with one track on
    it: its last corners the true ones, its tracker started on ``box``; the tracker's
    updates are counted."""
    image, plate, corners = scene()
    p = perception(plate, config)
    track = track_at(p, corners, box)
    tracker = AdaptiveTracker()
    tracker.init(image, box)
    track.tracker = tracker
    calls: list[int] = []
    update = tracker.update
    tracker.update = lambda img: calls.append(1) or update(img)  # type: ignore[method-assign]
    p.trackset.live["p"] = track
    return p, track, image, calls


ON_PLATE = (115.0, 90.0, 90.0, 60.0)


def test_a_track_coasts_two_frames_in_three_where_its_box_is_on_its_outline() -> None:
    p, track, image, calls = _one_track(PerceptionConfig(parallel_tracks=False), ON_PLATE)
    _, _, corners = scene()
    for n, (expected_calls, expected_coasted) in enumerate(((0, 1), (0, 2), (1, 0))):
        p.trackset.update(image)
        assert len(calls) == expected_calls and track.coasted == expected_coasted
        assert track.frames == n + 1  # followed, coasted or not (``young_cut_frames``)
        assert track.corners is not None and np.abs(track.corners - corners).max() < 0.5
        assert track.tried is None


@pytest.mark.parametrize("why", ["box off its outline", "box-only tracking", "every frame"])
def test_the_tracker_runs_where_a_coast_is_not_allowed(why: str) -> None:
    config = PerceptionConfig(parallel_tracks=False, refine_corners=why != "box-only tracking",
                              track_every_frames=1 if why == "every frame" else 3)
    box = (ON_PLATE[0] + 50.0, *ON_PLATE[1:]) if why == "box off its outline" else ON_PLATE
    p, track, image, calls = _one_track(config, box)
    p.trackset.update(image)
    assert len(calls) == 1 and track.coasted == 0
    if why == "box-only tracking":
        assert track.corners is None


def test_a_failed_coast_is_not_aligned_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where the plate is gone the coast's alignment fails; the tracker then runs, and the
    corners' alignment from the same start takes the coast's result (ECC is run once)."""
    p, track, _, calls = _one_track(PerceptionConfig(parallel_tracks=False), ON_PLATE)
    runs: list[int] = []
    inner = corners_module.ecc
    monkeypatch.setattr(corners_module, "ecc",
                        lambda *a, **k: runs.append(1) or inner(*a, **k))
    p.trackset.update(scene(seed=3, angle_deg=80.0)[0])  # another plate, turned
    assert len(calls) == 1 and track.misses == 1 and track.corners is None
    assert len(runs) == 1
