"""Where the perception's periodic work runs (issue 23): a track's appearance check runs
on the thread that updated it (housekeeping's one heavy step per call:
tests/test_perception.py)."""

from __future__ import annotations

import threading
from typing import Any

from companion.corners import Corners
from companion.perception import Perception, PerceptionConfig
from tests.test_perception import flight


def test_appearance_checks_run_on_the_thread_that_updated_the_track() -> None:
    threads: dict[str, set[str]] = {}
    original = Corners.check

    def check(self: Corners, track: Any, image: Any) -> float:
        threads.setdefault(track.landmark_id, set()).add(threading.current_thread().name)
        return original(self, track, image)

    Corners.check = check  # type: ignore[method-assign]
    try:
        _, perception, out = flight("street", range(300, 320),
                                    config=PerceptionConfig(parallel_tracks=True))
    finally:
        Corners.check = original  # type: ignore[method-assign]
    assert len(perception.tracks) >= 2, "fewer than two tracks: nothing runs in parallel"
    names = set().union(*threads.values())
    assert any(n.startswith("companion-tracks") for n in names), names  # the second thread
    assert threading.main_thread().name in names, names
    assert sum(r.fix is not None for r, _, _ in out) >= 15


def test_the_tracks_appearance_checks_are_spread_over_the_frames() -> None:
    """Each track is still checked every ``verify_every_frames`` frames, but not all tracks
    on the same frame (a frame that checked 3-4 plates cost 5-7 ms more of CPU)."""
    per_frame: dict[int, list[str]] = {}
    original = Corners.check
    frame_of: list[int] = [0]

    def check(self: Corners, track: Any, image: Any) -> float:
        per_frame.setdefault(frame_of[0], []).append(track.landmark_id)
        return original(self, track, image)

    original_process = Perception.process

    def process(self: Perception, frame: Any) -> Any:
        frame_of[0] = frame.index
        return original_process(self, frame)

    Corners.check = check  # type: ignore[method-assign]
    Perception.process = process  # type: ignore[method-assign]
    try:
        _, perception, out = flight("street", range(300, 330))
    finally:
        Corners.check = original  # type: ignore[method-assign]
        Perception.process = original_process  # type: ignore[method-assign]
    counts = [len(r.tracks) for r, _, _ in out]
    assert min(counts[5:]) >= 3, counts  # three tracks or more: there is something to spread
    late = {i: ids for i, ids in per_frame.items() if i >= 310}
    assert max(len(ids) for ids in late.values()) <= 2, late  # before: all 3-4 on one frame
    checked = [lid for ids in late.values() for lid in ids]
    for lid in perception.tracks:  # 20 frames: each track checked 4 times (every 5th)
        assert checked.count(lid) == 4, (lid, late)
