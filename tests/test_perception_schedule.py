"""Where the perception's periodic work runs (issue 23): no housekeeping call runs more
than one heavy step, and a track's appearance check runs on the thread that updated it."""

from __future__ import annotations

import dataclasses
import threading
from typing import Any

from companion.demo import map_landmarks
from companion.perception import Perception, PerceptionConfig
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sources.base import Frame
from tests.test_perception import flight


def test_housekeeping_with_no_track_runs_one_heavy_step_per_call() -> None:
    sim = Simulator(dataclasses.replace(load_scenario("survey"), seconds=60))
    landmarks, references = map_landmarks(sim)
    detected: list[int] = []

    def detect(_image: Any) -> list[Any]:
        detected.append(1)
        return []

    perception = Perception(sim.scenario.camera, landmarks, references, detect=detect)
    steps: list[list[str]] = []

    def counted(name: str) -> None:
        inner = getattr(perception, name)

        def run(*args: Any) -> Any:
            steps[-1].append(name)
            return inner(*args)

        setattr(perception, name, run)

    counted("_acquire")
    counted("_search")
    image, _ = sim.render(0)  # the sky above the survey: nothing there to find
    blank = image * 0
    for i in range(6):
        steps.append([])
        before = len(detected)
        perception.housekeeping(Frame(i, 10_000_000 + i * 33_333, blank))
        steps[-1] += ["detect"] * (len(detected) - before)
    perception.close()
    assert not perception.tracks
    assert all(len(s) <= 1 for s in steps), steps  # before: features + detector + search
    ran = {name for s in steps for name in s}
    assert ran == {"_acquire", "detect", "_search"}, steps  # each still gets its turn


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
