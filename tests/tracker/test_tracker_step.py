"""The tracker as a state and a step: ``step`` leaves its state as it was."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import numpy.typing as npt
import pytest

from tracker.config import TrackerConfig
from tracker.step import TrackState, box_of, coast, start, step

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


def test_a_coasted_frame_moves_the_estimate_and_particles_and_nothing_else(
    moving_sign: Scene,
) -> None:
    """``coast`` (a frame the tracker does not look at) moves the box by the shift and
    scales it, moves every particle with it, records the move in the history, leaves the
    state it was given as it was, and tracking goes on from there."""
    frames, truth = moving_sign
    state = start(frames[0], _box(truth[0]), CFG)
    rng = np.random.default_rng(3)
    state, _ = step(state, frames[1], CFG, rng)
    before = _snapshot(state)
    moved, box = coast(state, (4.0, -3.0), 1.1, CFG)
    x, y, w, h = box_of(state, state.estimate)
    assert box == pytest.approx((x + 4.0 + w / 2 - 1.1 * w / 2, y - 3.0 + h / 2 - 1.1 * h / 2,
                                 1.1 * w, 1.1 * h))
    np.testing.assert_allclose(moved.particles[:, :2], state.particles[:, :2] + [4.0, -3.0])
    np.testing.assert_allclose(moved.particles[:, 2], state.particles[:, 2] * 1.1)
    assert moved.history[-1] == pytest.approx(tuple(np.add(state.estimate[:2], (4.0, -3.0))))
    assert moved.frames == state.frames + 1 and moved.model is state.model
    for old, now in zip(before, _snapshot(state), strict=True):
        np.testing.assert_array_equal(old, now)
    _, result = step(moved, frames[2], CFG, rng)
    assert result.box is not None


def test_a_lost_target_does_not_coast(hidden_sign: Scene) -> None:
    frames, truth = hidden_sign
    state = start(frames[0], _box(truth[0]), CFG)
    state = replace(state, lost_frames=1)
    with pytest.raises(ValueError, match="lost"):
        coast(state, (0.0, 0.0), 1.0, CFG)
