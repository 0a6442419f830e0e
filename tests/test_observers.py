"""Observers keep the truth beside the results; sources say what they know by protocol."""

from __future__ import annotations

import asyncio
import dataclasses
from typing import Any

import numpy as np
import pytest

from companion.app import FrameResult
from companion.cli.run_cmd import open_run_source, with_source_references
from companion.core.frames import Frame
from companion.flightmap import PracticalMap
from companion.landmarks.geodesy import LocalFrame
from companion.observers import FixTruths, TruthTags
from companion.perception_types import TrackView
from companion.replay_score import track_boxes
from companion.settings import SIM_LAYERS, load_settings
from companion.simulated import register
from companion.sources.base import KnowsCamera, KnowsReferences, KnowsTruth
from tracker.pose.types import MapLandmark, PoseFix

LANDMARKS = [MapLandmark("a", (10.0, 0.0, 0.0), 1.0, 1.0, 0.0),
             MapLandmark("b", (0.0, 20.0, 0.0), 1.0, 1.0, 0.0)]


def _frame(index: int) -> Frame:
    return Frame(index, 1000 * index, np.zeros((2, 2, 3), np.uint8))


def _result(index: int, north_m: float | None) -> FrameResult:
    fix = None if north_m is None else PoseFix(
        0, (north_m, 0.0, 0.0), (0.0, 0.0, 0.0), np.eye(6), 90, ("a", "b"), "pnp")
    return FrameResult(index, 1000 * index, fix=fix)


def test_truth_goes_into_the_pose_report_not_into_the_result() -> None:
    truths = {1: (3.0, 4.0, 0.0), 2: None}
    tags = TruthTags(lambda f: truths.get(f.index))
    fixed = _result(1, 0.0)
    before = repr(fixed)
    tags.on_result(_frame(1), fixed)
    assert tags.pose_fields(fixed) == {"truth_position_ned_m": [3.0, 4.0, 0.0],
                                       "truth_error_m": 5.0}
    assert repr(fixed) == before  # the frozen result untouched
    unknown = _result(2, 1.0)  # a fix whose frame's truth is unknown: nothing added
    tags.on_result(_frame(2), unknown)
    assert tags.pose_fields(unknown) == {}
    assert tags.pose_fields(fixed) == {}  # only for the frame it last saw


def test_fix_truths_keep_each_fix_with_its_truth_and_landmark_distance() -> None:
    truths = FixTruths(lambda f: (0.0, 0.0, 0.0) if f.index != 3 else None, LANDMARKS)
    for i, north in [(1, 0.5), (2, None), (3, 1.0), (4, -1.0)]:
        truths.on_result(_frame(i), _result(i, north))
    assert [(f.position_ned_m[0], t, d) for f, t, d in truths.fixes] == [
        (0.5, (0.0, 0.0, 0.0), 15.0), (-1.0, (0.0, 0.0, 0.0), 15.0)]


def test_a_track_lost_in_its_frame_is_not_scored_live() -> None:
    """The replay scores tracks still live after the frame: one dropped after the fix is
    reported with its box and its lost event (its landmark's next track starts afresh)."""
    result = FrameResult(5, 0, tracks=(TrackView("a", (1, 2, 3, 4), 0.9, (0,), None),
                                       TrackView("b", (5, 6, 7, 8), 0.9, (0,), None)),
                         events=({"event": "lost", "landmark": "b", "why": "rejected"},
                                 {"event": "lost", "landmark": "c"}))
    assert track_boxes(result) == {"a": (1.0, 2.0, 3.0, 4.0)}


def test_run_takes_what_a_simulated_camera_says_it_knows() -> None:
    """run takes a simulated camera's truth, textures and camera through the protocols of
    companion.sources.base (it never imports the simulator: tests/test_import_layers.py)."""
    register()  # as the command line does at start
    settings = load_settings(shipped=SIM_LAYERS, sets=['source.spec="sim:hover"',
                                                       "source.realtime=false"])
    pmap = PracticalMap((), {}, LocalFrame(0.0, 0.0, 0.0))

    async def opened() -> Any:
        return await open_run_source(settings, object(), pmap)  # type: ignore[arg-type]

    run_source = asyncio.run(opened())
    source = run_source.source
    try:
        assert all(isinstance(source, p) for p in (KnowsTruth, KnowsReferences, KnowsCamera))
        sim = source.sim  # type: ignore[attr-defined]
        assert run_source.camera == sim.scenario.camera != settings.camera
        frame = asyncio.run(source.recv())
        assert run_source.truth_of is not None
        assert run_source.truth_of(frame) == pytest.approx(
            tuple(sim.state_at(0.0).position_ned_m))
        refs = source.reference_images()
        assert refs and set(refs) <= {lm.landmark_id for lm in sim.world.landmarks}
        own = next(iter(refs))
        mapped = with_source_references(dataclasses.replace(
            pmap, references={own: np.zeros((4, 4, 3), np.uint8)},
            unusable={k: "no image" for k in refs}), source)
        assert set(mapped.references) == set(refs) and mapped.unusable == {}
        assert mapped.references[own].shape == (4, 4, 3)  # the map's own image wins
    finally:
        source.close()
