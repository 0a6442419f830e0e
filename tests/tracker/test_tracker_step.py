"""The tracker as a state and a step: ``step`` leaves its state as it was."""

from __future__ import annotations

import copy

import numpy as np
import numpy.typing as npt
import pytest

from tracker.config import TrackerConfig
from tracker.step import TrackState, start, step

Scene = tuple[list[npt.NDArray[np.uint8]], npt.NDArray[np.float64]]
CFG = TrackerConfig()


def _box(truth: npt.NDArray[np.float64]) -> tuple[float, float, float, float]:
    return (float(truth[0]), float(truth[1]), float(truth[2]), float(truth[3]))


def _run(
    state: TrackState, frames: list[npt.NDArray[np.uint8]], rng: np.random.Generator
) -> list[tuple[object, float, tuple[int, ...]]]:
    out = []
    for frame in frames:
        state, r = step(state, frame, CFG, rng)
        out.append((r.box, r.confidence, r.features))
    return out


def _snapshot(state: TrackState) -> list[npt.NDArray[np.float64]]:
    """Copies of the arrays a careless step would write into."""
    return [
        state.estimate.copy(), state.particles.copy(), state.model.recent.copy(),
        state.gain.gain.copy(), state.refiner.template().copy(),
    ]


@pytest.mark.parametrize("fixture", ["moving_sign", "hidden_sign"])
def test_a_step_leaves_its_state_as_it_was(fixture: str, request: pytest.FixtureRequest) -> None:
    """Stepping on from a saved state twice (tracking, and on the hidden sign lost and found
    again) gives the same results, and the saved state does not change."""
    frames, truth = request.getfixturevalue(fixture)
    state = start(frames[0], _box(truth[0]), CFG)
    rng = np.random.default_rng(5)
    for frame in frames[1:27]:
        state, _ = step(state, frame, CFG, rng)
    if fixture == "hidden_sign":
        assert state.lost_frames > 0  # the sign is hidden from frame 20: the saved state is lost
    before = _snapshot(state)
    again = copy.deepcopy(rng)
    first = _run(state, frames[27:52], rng)
    second = _run(state, frames[27:52], again)
    assert first == second
    assert any(box is not None for box, _, _ in first)
    for old, now in zip(before, _snapshot(state), strict=True):
        np.testing.assert_array_equal(old, now)
    assert state.frames == 26
