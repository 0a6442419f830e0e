"""With nothing in view, acquisition searches on one frame in ``idle_search_every_frames``
(issue 23: searching back to back took a core); a track just lost is searched for at the
full rate for ``idle_after_s``.  The acquirers here only record the frames they ran on."""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np

from companion.acquirers import Sighting, Starter
from companion.acquisition import Acquisition
from companion.perception_types import Occupancy, PerceptionConfig, Start

FPS = 30
IMAGE = np.zeros((48, 64, 3), np.uint8)


class Recorder:
    """An acquirer that finds nothing and notes the frame it was asked on."""

    def __init__(self) -> None:
        self.frames: list[int] = []
        self.index = -1

    def find(self, sight: Sighting, earlier: Sequence[Start] = ()) -> list[Start]:
        self.frames.append(self.index)
        return []


def schedule(frames: range, tracked_until: int = -1, light_step_at: int = -1,
             **config: float) -> tuple[list[int], list[int], list[int]]:
    """The frames feature matching, the detector and the template search ran on, with a
    track running on frames < ``tracked_until`` and a light step before ``light_step_at``."""
    features, detector, search, prediction = Recorder(), Recorder(), Recorder(), Recorder()
    acq = Acquisition(PerceptionConfig(**config),  # type: ignore[arg-type]
                      cast(Starter, None), features, prediction, search, detector)
    for i in frames:
        for r in (features, detector, search):
            r.index = i
        if i == light_step_at:
            acq.due_now()
        seen = Occupancy(tracked=frozenset({"wall-01"}) if i < tracked_until else frozenset())
        acq.run(i, round(i * 1e6 / FPS), Sighting(IMAGE, seen))
    return features.frames, detector.frames, search.frames


def test_nothing_in_view_is_searched_on_one_frame_in_six() -> None:
    features, detector, search = schedule(range(60))
    assert features == list(range(0, 60, 6))
    # the detector finds nothing, so the template search runs on the same call
    assert detector == search == list(range(0, 60, 6))


def test_every_frame_when_asked() -> None:
    features, detector, _ = schedule(range(20), idle_search_every_frames=1)
    assert features == detector == list(range(20))


def test_a_track_just_lost_is_searched_for_at_the_full_rate_first() -> None:
    # tracked on frames 0-29; lost at frame 30 (1.0 s); idle from 1.0 s after the last
    # frame it was seen on (frame 29): frame 60 is the first paced one
    features, detector, _ = schedule(range(90), tracked_until=30)
    lost = [i for i in features if i >= 30]
    assert lost[:31] == list(range(30, 61)), lost
    assert lost[31:] == list(range(66, 90, 6)), lost
    # no fix all along: the search, too, runs on every frame once the track is gone
    assert [i for i in detector if i >= 30] == lost, detector


def test_a_light_step_searches_at_once() -> None:
    features, _, _ = schedule(range(30), light_step_at=8)
    assert features == [0, 6, 8, 14, 20, 26]
