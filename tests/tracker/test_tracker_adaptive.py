"""The adaptive tracker's behaviour through its public API."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from tracker import AdaptiveTracker, TrackerConfig
from tracker.config import replace
from tracker.features import GRAY_FEATURES

Scene = tuple[list[npt.NDArray[np.uint8]], npt.NDArray[np.float64]]


def _centre(box: tuple[float, float, float, float] | None) -> npt.NDArray[np.float64]:
    assert box is not None
    return np.array([box[0] + box[2] / 2, box[1] + box[3] / 2])


def _error(box: tuple[float, float, float, float] | None, truth: npt.NDArray) -> float:
    return float(np.linalg.norm(_centre(box) - _centre((truth[0], truth[1], truth[2], truth[3]))))


def _run(t: AdaptiveTracker, frames: list[npt.NDArray[np.uint8]], truth: npt.NDArray) -> list:
    t.init(frames[0], tuple(truth[0]))
    return [t.update(f) for f in frames[1:]]


def test_follows_a_moving_sign(moving_sign: Scene) -> None:
    frames, truth = moving_sign
    results = _run(AdaptiveTracker(seed=0), frames, truth)
    errors = [_error(r.box, t) for r, t in zip(results, truth[1:], strict=True)]
    # the estimate never leaves the sign (half its width is 28 px) and is close on average
    assert max(errors) < 20.0, f"centre error up to {max(errors):.1f} px"
    assert np.mean(errors) < 5.0, f"mean centre error {np.mean(errors):.1f} px"
    assert all(r.cue == "colour" and r.particles == 20 for r in results)
    assert all(0.0 <= r.confidence <= 1.0 for r in results)
    assert np.mean([r.confidence for r in results]) > 0.5
    assert len(results[-1].features) == 3 and all(0 <= f < 49 for f in results[-1].features)


def test_same_seed_same_track_and_no_global_random_state(moving_sign: Scene) -> None:
    frames, truth = moving_sign
    a = _run(AdaptiveTracker(seed=3), frames[:15], truth)
    np.random.seed(123)  # global state must not matter
    b = _run(AdaptiveTracker(seed=3), frames[:15], truth)
    assert [r.box for r in a] == [r.box for r in b]


def test_reports_lost_while_hidden_and_reacquires(hidden_sign: Scene) -> None:
    frames, truth = hidden_sign
    results = _run(AdaptiveTracker(seed=0), frames, truth)
    boxes = [r.box for r in results]  # results[i] is frame i + 1
    assert all(b is not None for b in boxes[:19]), "lost while the sign was visible"
    hidden = boxes[19:34]
    assert sum(b is None for b in hidden) >= 10, "never reported the hidden target lost"
    assert all(r.lost == (r.box is None) for r in results)
    back = boxes[40:]
    assert all(b is not None for b in back), "did not re-acquire the sign"
    err = [_error(b, t) for b, t in zip(back, truth[41:], strict=True)]
    assert max(err) < 20.0


def test_grayscale_input_uses_the_grey_features(moving_sign: Scene) -> None:
    frames, truth = moving_sign
    grey = [np.repeat(f.mean(axis=2, keepdims=True).astype(np.uint8), 3, axis=2) for f in frames]
    t = AdaptiveTracker(seed=0)
    results = _run(t, grey[:30], truth)
    assert t.cue == "grayscale"
    assert all(r.cue == "grayscale" for r in results)
    assert set(results[-1].features) <= set(GRAY_FEATURES)
    err = [_error(r.box, x) for r, x in zip(results, truth[1:30], strict=True)]
    assert np.median(err) < 10.0


def test_likelihood_images_show_the_target(moving_sign: Scene) -> None:
    frames, truth = moving_sign
    t = AdaptiveTracker(seed=0)
    t.init(frames[0], tuple(truth[0]))
    images = t.likelihood_images(frames[0])
    assert [fid for fid, _ in images] == list(t.features)
    x, y, w, h = (int(v) for v in truth[0])
    for _, lik in images:
        assert lik.shape == frames[0].shape[:2]
        assert lik[y : y + h, x : x + w].mean() > lik.mean()


@pytest.mark.parametrize(
    ("box", "word"),
    [
        ((-5, 10, 20, 20), "inside"),
        ((300, 10, 40, 20), "inside"),
        ((10, 10, 0, 20), "width and height"),
        ((10, 10, float("nan"), 20), "finite"),
        ((1, 2, 3), "four"),
        ("abcd", "four numbers"),
    ],
)
def test_bad_box_is_a_value_error_naming_box(moving_sign: Scene, box: object, word: str) -> None:
    frames, _ = moving_sign
    with pytest.raises(ValueError, match=rf"^box: .*{word}"):
        AdaptiveTracker().init(frames[0], box)  # type: ignore[arg-type]


def test_bad_frames_are_value_errors_naming_image(moving_sign: Scene) -> None:
    frames, truth = moving_sign
    t = AdaptiveTracker()
    with pytest.raises(ValueError, match=r"^image_bgr: .*dtype uint8"):
        t.init(frames[0].astype(np.float32), tuple(truth[0]))
    with pytest.raises(ValueError, match=r"^image_bgr: .*3 channels"):
        t.init(frames[0][:, :, 0], tuple(truth[0]))
    with pytest.raises(ValueError, match=r"^image_bgr: .*numpy array"):
        t.init([[1, 2]], tuple(truth[0]))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^update: call init"):
        t.update(frames[0])
    t.init(frames[0], tuple(truth[0]))
    with pytest.raises(ValueError, match=r"^image_bgr: .*same size"):
        t.update(frames[1][:100])
    with pytest.raises(ValueError, match=r"^image_bgr: .*3 channels"):
        t.update(np.zeros((240, 320, 4), np.uint8))


def test_bad_config_is_a_value_error_naming_the_field() -> None:
    with pytest.raises(ValueError, match=r"^config\.filter\.particles: expected a value >= 4"):
        AdaptiveTracker(replace(TrackerConfig(), particles=2))


def test_rank_phase_shifts_the_periodic_reranking(moving_sign: Scene) -> None:
    """Trackers started together re-rank on different frames when given different phases
    (the live pipeline's per-frame cost stays even); the phase moves the schedule only."""
    frames, truth = moving_sign
    every = TrackerConfig().features.rerank_every_frames

    def rerank_frames(phase: int) -> list[int]:
        """The frames after which the state says the features were just ranked."""
        t = AdaptiveTracker(seed=0)
        t.init(frames[0], tuple(truth[0]), rank_phase=phase)
        ranked: list[int] = []
        for now, image in enumerate(frames[1:31], start=1):
            t.update(image)
            if t.state.since_rank == 0:
                ranked.append(now)
        return ranked

    assert rerank_frames(0)[:3] == [every, 2 * every, 3 * every]
    assert rerank_frames(4)[:3] == [every - 4, 2 * every - 4, 3 * every - 4]
