"""How one frame's track updates share the two threads (issue 23): one queue, the dearest
first, each thread taking the next as it is free; and the particle tracker's turns spread
over the frames, never later than ``track_every_frames`` apart."""

from __future__ import annotations

import threading
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from companion.corners import Corners
from companion.perception_types import PerceptionConfig, Track
from companion.tracks import TrackSet
from tracker.acquire import ReferenceMatcher
from tracker.camera import CameraModel

IMAGE = np.zeros((48, 64, 3), np.uint8)


def trackset(parallel: bool = True, every: int = 3) -> TrackSet:
    config = PerceptionConfig(parallel_tracks=parallel, track_every_frames=every)
    return TrackSet(config, Corners(CameraModel(), config, {}, ReferenceMatcher()))


def track(lid: str, cost_ms: float = 0.0, coasted: int = 0) -> Track:
    """A track whose tracker's turn is due when ``coasted`` reaches 2 (of 3)."""
    t = Track(lid, SimpleNamespace(state=SimpleNamespace(lost_frames=0)),  # type: ignore[arg-type]
              (10.0, 20.0, 30.0, 40.0), None)
    t.corners = np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 8.0], [0.0, 8.0]])
    t.cost_s, t.coasted = cost_ms / 1e3, coasted
    return t


def test_a_thread_held_by_the_dearest_track_leaves_the_others_to_the_other_thread(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The track whose turn is due goes first, then the others by their last cost; while
    one thread is held by the first, the other takes every other track.  (A fixed split,
    every other track to the second thread, would leave ``small`` behind ``due`` on one
    thread: ``due`` then waits for it in vain and the test fails; taken in the given order,
    ``late`` would run before ``due`` or before ``big``.)"""
    ts = trackset()
    due, big, late = track("due", 1.0, coasted=2), track("big", 5.0), track("late", 3.0)
    small = track("small", 2.0)
    others_done = threading.Event()
    done: list[str] = []
    ran: dict[str, list[str]] = {}

    def update(self: TrackSet, t: Track, *_: Any) -> bool:
        ran.setdefault(threading.current_thread().name, []).append(t.landmark_id)
        if t is due:
            assert others_done.wait(10.0), "another track waited behind the held one"
        else:
            done.append(t.landmark_id)
            if len(done) == 3:
                others_done.set()
        return t is not big  # the results come back in the tracks' order

    monkeypatch.setattr(TrackSet, "_update_track", update)
    try:
        alive = ts._update_all([late, due, big, small], IMAGE, [False] * 4)
    finally:
        ts.close()
    assert alive == [True, True, False, True]
    assert sorted(ran.values(), key=len) == [["due"], ["big", "late", "small"]]


def test_the_last_cost_of_each_track_is_kept() -> None:
    ts = trackset(parallel=False)
    t = track("a", 0.0, coasted=2)
    t.tracker = SimpleNamespace(  # type: ignore[assignment]
        state=SimpleNamespace(lost_frames=0),
        update=lambda image: SimpleNamespace(box=None, confidence=0.0))
    assert ts._update_all([t], IMAGE, [False]) == [False]  # the tracker lost it
    assert t.cost_s > 0.0


@pytest.mark.parametrize(("coasted", "early"), [
    ((1, 1, 0), {"b"}),    # turns due in 1, 1 and 2 frames, none now: "b" takes its turn now
    ((2, 1, 1), set()),    # "a"'s turn is now: nothing brought forward
    ((1, 0), set()),       # different frames already
    ((0, 0, 0), {"b"}),    # all in 2 frames: one now (the next frame spreads the other two)
])
def test_a_turn_is_brought_forward_onto_a_frame_without_one(
    coasted: tuple[int, ...], early: set[str]
) -> None:
    ts = trackset()
    tracks = [track(lid, coasted=c) for lid, c in zip("abc", coasted, strict=False)]
    ts._early = frozenset({"c"})  # the last frame's choice does not carry over
    ts._spread_turns(tracks)
    assert ts._early == early
    ts.close()


@pytest.mark.parametrize("parallel", [False, True])
def test_three_tracks_started_together_soon_take_one_turn_a_frame(
    monkeypatch: pytest.MonkeyPatch, parallel: bool
) -> None:
    """Three tracks acquired on one frame would take their turns on the same frames for
    good; spread, after a few frames each frame has one turn, and no track ever waits
    longer than ``track_every_frames`` for its turn."""
    turns: list[list[str]] = []

    def update(self: TrackSet, t: Track, *_: Any) -> bool:
        if self._turn_due(t):  # the tracker's turn (a coast that held otherwise)
            t.coasted = 0
            turns[-1].append(t.landmark_id)
        else:
            t.coasted += 1
        return True

    monkeypatch.setattr(TrackSet, "_update_track", update)
    ts = trackset(parallel)
    for lid in "abc":
        ts.live[lid] = track(lid, coasted=2)  # all due on the first frame
    for _ in range(30):
        turns.append([])
        ts.update(IMAGE)
    ts.close()
    assert sorted(turns[0]) == ["a", "b", "c"]
    assert [len(t) for t in turns[4:]] == [1] * 26
    for lid in "abc":
        frames = [i for i, t in enumerate(turns) if lid in t]
        assert frames[0] == 0 and max(np.diff(frames)) <= 3
