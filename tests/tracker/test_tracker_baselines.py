"""Baselines share the tracker interface and track an easy target."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from companion.errors import InputError
from companion.evaluation.runner import make_tracker
from tracker import MeanShiftTracker, MilTracker, ParticleFilterTracker
from tracker.baselines import csrt_available
from tracker.types import Tracker

Scene = tuple[list[npt.NDArray[np.uint8]], npt.NDArray[np.float64]]


@pytest.mark.parametrize("make", [ParticleFilterTracker, MeanShiftTracker, MilTracker])
def test_baseline_follows_the_sign(make: type, moving_sign: Scene) -> None:
    frames, truth = moving_sign
    tracker: Tracker = make(seed=0)
    tracker.init(frames[0], tuple(truth[0]))
    errors = []
    for frame, t in zip(frames[1:30], truth[1:30], strict=True):
        r = tracker.update(frame)
        assert r.box is not None and 0.0 <= r.confidence <= 1.0 + 1e-9
        c = np.array([r.box[0] + r.box[2] / 2, r.box[1] + r.box[3] / 2])
        errors.append(np.linalg.norm(c - (t[:2] + t[2:] / 2)))
    assert np.median(errors) < 10.0


def test_particle_filter_uses_120_particles(moving_sign: Scene) -> None:
    frames, truth = moving_sign
    pf = ParticleFilterTracker(seed=0)
    pf.init(frames[0], tuple(truth[0]))
    assert pf.update(frames[1]).particles == 120


@pytest.mark.parametrize("make", [ParticleFilterTracker, MeanShiftTracker, MilTracker])
def test_baselines_reject_bad_input(make: type, moving_sign: Scene) -> None:
    frames, truth = moving_sign
    tracker = make(seed=0)
    with pytest.raises(ValueError, match=r"^box: "):
        tracker.init(frames[0], (0, 0, 0, 5))
    tracker.init(frames[0], tuple(truth[0]))
    with pytest.raises(ValueError, match=r"^image_bgr: "):
        tracker.update(frames[1][:, :, :2])


def test_mil_refuses_boxes_it_cannot_handle(moving_sign: Scene) -> None:
    """Tiny boxes hang OpenCV's TrackerMIL and whole-frame boxes make it assert: ValueError."""
    frames, _ = moving_sign
    with pytest.raises(ValueError, match=r"^box: TrackerMIL needs width and height >= 6"):
        MilTracker().init(frames[0], (10, 10, 4, 4))
    h, w = frames[0].shape[:2]
    with pytest.raises(ValueError, match=r"^box: TrackerMIL cannot sample"):
        MilTracker().init(frames[0], (0, 0, w, h))


def test_csrt_without_contrib_is_one_clear_error() -> None:
    """The project's OpenCV has no TrackerCSRT: asking for the peer says so in one line."""
    if csrt_available():
        pytest.skip("this OpenCV has contrib's TrackerCSRT")
    with pytest.raises(InputError, match="TrackerCSRT"):
        make_tracker("csrt")
