"""Where the perception's periodic work runs (issue 23): a track's appearance check runs
on the thread that updated it (housekeeping's one heavy step per call:
tests/test_perception.py)."""

from __future__ import annotations

import threading
from typing import Any

from companion.perception import Perception, PerceptionConfig
from tests.test_perception import flight


def test_appearance_checks_run_on_the_thread_that_updated_the_track() -> None:
    threads: dict[str, set[str]] = {}
    original = Perception._check_track

    def check(self: Perception, track: Any, image: Any) -> None:
        threads.setdefault(track.landmark_id, set()).add(threading.current_thread().name)
        original(self, track, image)

    Perception._check_track = check  # type: ignore[method-assign]
    try:
        _, perception, out = flight("street", range(300, 320),
                                    config=PerceptionConfig(parallel_tracks=True))
    finally:
        Perception._check_track = original  # type: ignore[method-assign]
    assert len(perception.tracks) >= 2, "fewer than two tracks: nothing runs in parallel"
    names = set().union(*threads.values())
    assert any(n.startswith("companion-tracks") for n in names), names  # the second thread
    assert threading.main_thread().name in names, names
    assert sum(r.fix is not None for r, _, _ in out) >= 15
