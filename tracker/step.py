"""One frame of the adaptive tracker as a function: ``step(state, frame, config, rng)``.

The paper's loop (sec. 3-4), in the order :func:`_track` runs it:

1. propagate the particles with the adaptive noise of eq. 1 (:mod:`tracker.particles`),
   plus a CONDENSATION drift;
2. cut the search window around the last estimate, undo the illumination gain
   (:mod:`tracker.illumination`), back-project the selected features' log-likelihood ratios
   (eq. 8, fig. 5) into a likelihood image (:mod:`tracker.target_model`);
3. mean-shift one set of particles on that image, leave the other where it is;
4. weigh every particle by ``exp(-omega s^2)`` from the Bhattacharyya distance of its
   kernel histograms (eq. 2-4, :mod:`tracker.appearance`), times the likelihood image's vote;
5. drop particles below ``weight_threshold``; the estimate is the weighted mean or the best
   particle, whichever matches the model better; resample systematically;
6. refine the estimate on the template and read its size (:mod:`tracker.refine`);
7. accept: lost bookkeeping, model update, and every ``rerank_every_frames`` frames (or when
   the confidence drops) the features re-ranked by variance ratio (eq. 6-7); after a trusted
   frame the gain and the template learn.

While the target is lost :func:`_search_lost` runs instead: a widening window, the mode of
the smoothed likelihood plus scattered mean-shifted samples, confirmed by the template.

:class:`TrackState` is immutable; ``step`` returns a new one and leaves its argument as it
was (the template and size filters are forked, :meth:`tracker.refine.Refiner.fork`).  The
only thing a step changes is ``rng``, drawn in a fixed order.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
import numpy.typing as npt

from tracker import illumination
from tracker.appearance import bhattacharyya, particle_likelihood
from tracker.config import TrackerConfig
from tracker.features import GRAY_FEATURES, is_grayscale
from tracker.illumination import Gain
from tracker.particles import (
    integral_images,
    mean_shift,
    motion_noise,
    propagate,
    systematic_resample,
    weighted_estimate,
)
from tracker.refine import Refiner
from tracker.target_model import (
    Counted,
    FirstFrame,
    TargetModel,
    kernel,
    likelihood,
    llr_factor,
    rank,
)
from tracker.template import as_float
from tracker.types import Box, TrackResult
from tracker.window import Window, cut_window, work_factor

FloatArray = npt.NDArray[np.float64]
Frame = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class TrackState:
    """Everything the tracker knows about one target between two frames."""

    shape: tuple[int, ...]  # the frames' shape (every frame must have it)
    first: FirstFrame  # the cue, candidate features and first box the model is anchored to
    size: tuple[float, float]  # (width, height) at scale 1 in pixels (the aspect can change)
    estimate: FloatArray  # (x, y, s): the last estimate's centre (pixels) and scale
    particles: FloatArray  # (N, 3) rows (x, y, s)
    model: TargetModel  # the selected features, their LLR and the model histograms
    gain: Gain  # the illumination gain
    refiner: Refiner  # the template and size filters
    history: tuple[tuple[float, float], ...]  # the last centres (eq. 1's noise, the drift)
    since_rank: int  # frames since the features were last ranked
    low_frames: int  # consecutive frames of low confidence
    lost_frames: int  # 0 while tracking; frames since the target was lost + 1
    frames: int = 0  # frames stepped since the first


def half_size(size: tuple[float, float], scale: FloatArray | float, window: Window) -> FloatArray:
    """Half box sizes in patch pixels for one or more scales -> (P, 2)."""
    w0, h0 = size
    half = np.array([w0 * window.fx / 2.0, h0 * window.fy / 2.0])
    return np.multiply.outer(np.asarray(scale, dtype=np.float64).reshape(-1), half)


def _window(
    size: tuple[float, float], image: Frame, at: FloatArray, extra_px: float, widen: float,
    cfg: TrackerConfig,
) -> Window:
    """The search window around the box ``at``: ``search_margin_frac`` around it, ``widen``
    times, plus ``extra_px``, downscaled so the box covers about ``work_area_px``."""
    w, h = size[0] * at[2], size[1] * at[2]
    grow = (0.5 + cfg.filter.search_margin_frac) * widen
    extent = (w * grow + extra_px, h * grow + extra_px)
    factor = work_factor(w, h, cfg.filter.work_area_px)
    return cut_window(image, (at[0], at[1]), extent, factor)


def box_of(state: TrackState, at: FloatArray) -> Box:
    """The box ``(x, y, w, h)`` of the estimate ``at`` = (x, y, s)."""
    w, h = state.size[0] * at[2], state.size[1] * at[2]
    return (float(at[0] - w / 2), float(at[1] - h / 2), float(w), float(h))


def _inside(shape: tuple[int, ...], at: FloatArray) -> FloatArray:
    """``at`` with its centre clipped to the frame (the target's centre is in view)."""
    h, w = shape[:2]
    return np.array([min(max(at[0], 0.0), w), min(max(at[1], 0.0), h), at[2]])


def _result(
    state: TrackState, box: Box | None, confidence: float, cfg: TrackerConfig
) -> TrackResult:
    return TrackResult(
        box=box,
        confidence=confidence,
        features=state.model.features,
        lost=box is None,
        cue=state.first.cue,
        particles=cfg.filter.particles,
    )


def start(image: Frame, box: Box, cfg: TrackerConfig, rank_phase: int = 0) -> TrackState:
    """The state on the first frame, the target inside ``box`` = (x, y, w, h) (checked).

    ``rank_phase`` shifts the periodic re-ranking by that many frames.
    """
    x, y, w, h = box
    size = (w, h)
    estimate = np.array([x + w / 2.0, y + h / 2.0, 1.0])
    window = _window(size, image, estimate, 0.0, 1.0, cfg)
    grey = is_grayscale(window.patch, cfg.features.gray_tolerance)
    candidates = GRAY_FEATURES if grey else tuple(range(49))
    centre = window.to_patch(estimate[None, :2])
    first = FirstFrame("grayscale" if grey else "colour", candidates, window, centre)
    half = half_size(size, 1.0, window)
    refiner = Refiner(
        cfg.refine, as_float(window.patch, grey), centre[0], 2.0 * half[0],
        image, estimate[:2], np.array(size),
    )
    gain = illumination.start(
        illumination.box_mean(window, estimate[:2], half[0], cfg.illumination), image
    )
    model, p_first = rank(window, centre[0], half[0], first, half, True, cfg)
    return TrackState(
        shape=image.shape,
        first=replace(first, p=p_first),
        size=size,
        estimate=estimate,
        particles=np.tile(estimate, (cfg.filter.particles, 1)),
        model=model,
        gain=gain,
        refiner=refiner,
        history=((estimate[0], estimate[1]),),
        since_rank=rank_phase % cfg.features.rerank_every_frames,
        low_frames=0,
        lost_frames=0,
    )


def step(
    state: TrackState, frame: Frame, cfg: TrackerConfig, rng: np.random.Generator
) -> tuple[TrackState, TrackResult]:
    """Track into the next frame: the new state and the result (``box`` None while lost)."""
    state = replace(state, refiner=state.refiner.fork(), frames=state.frames + 1)
    if state.lost_frames > 0:
        return _search_lost(state, frame, cfg, rng)
    return _track(state, frame, cfg, rng)


def coast(
    state: TrackState, shift: tuple[float, float], ratio: float, cfg: TrackerConfig
) -> tuple[TrackState, Box]:
    """A frame the tracker does not look at: its estimate and particles moved by ``shift``
    (pixels) and scaled by ``ratio``, as something else found the target moved (the
    companion's corner alignment, issue 23); the move enters the history (eq. 1's noise
    and the drift), nothing learns, and ``since_rank`` stays: re-ranking counts the
    frames the tracker looked at.  Only while the target is tracked (not lost)."""
    if state.lost_frames > 0:
        raise ValueError("coast: the target is lost")
    move = np.array([shift[0], shift[1]])
    scale = min(max(state.estimate[2] * ratio, cfg.motion.min_scale), cfg.motion.max_scale)
    estimate = _inside(state.shape, np.array([*(state.estimate[:2] + move), scale]))
    particles = state.particles.copy()
    particles[:, :2] += estimate[:2] - state.estimate[:2]  # as the estimate moved (clipped)
    particles[:, 2] *= scale / state.estimate[2]
    history = _pushed(state.history, estimate, cfg)
    state = replace(state, estimate=estimate, particles=particles, history=history,
                    frames=state.frames + 1)
    return state, box_of(state, estimate)


def _pushed(
    history: tuple[tuple[float, float], ...], estimate: FloatArray, cfg: TrackerConfig
) -> tuple[tuple[float, float], ...]:
    """The recent centres with ``estimate``'s added, as many as eq. 1's noise uses."""
    keep = cfg.motion.motion_history_frames + 1
    return (*history, (float(estimate[0]), float(estimate[1])))[-keep:]


def _noise(state: TrackState, cfg: TrackerConfig) -> float:
    """Eq. 1's noise from the recent steps, in fractions of the box side."""
    m = cfg.motion
    side = 0.5 * (state.size[0] + state.size[1]) * state.estimate[2]
    return motion_noise(
        list(state.history),
        m.motion_history_frames,
        m.motion_gain,
        m.motion_min_frac * side,
        m.motion_max_frac * side,
        m.motion_initial_frac * side,
    )


def _propagate(
    state: TrackState, noise: float, cfg: TrackerConfig, rng: np.random.Generator
) -> FloatArray:
    """Eq. 1 plus the CONDENSATION drift (the mean velocity of the recent steps)."""
    m = cfg.motion
    particles = propagate(state.particles, noise, m.scale_noise, (m.min_scale, m.max_scale), rng)
    if m.drift_gain > 0 and len(state.history) >= 2:
        steps = np.diff(np.asarray(state.history), axis=0)
        particles[:, :2] += m.drift_gain * steps.mean(axis=0)
    return particles


def _weigh(
    state: TrackState, window: Window, particles: FloatArray, cfg: TrackerConfig
) -> tuple[Counted, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Steps 2-5 on the (compensated) window: the selected features' counted planes, the
    particles (the first set mean-shifted on the likelihood image), their weights above the
    threshold, the two candidate estimates (weighted mean, best particle), their histograms
    and the model's."""
    f = cfg.filter
    planes, lik = likelihood(window.patch, state.model, cfg)
    centres = window.to_patch(particles[:, :2])
    halves = half_size(state.size, particles[:, 2], window)
    shifted = round(f.particles * f.mean_shift_fraction)
    tables = integral_images(np.maximum(lik, 0.0))
    if shifted and f.mean_shift_iterations:
        centres[:shifted] = mean_shift(
            tables, centres[:shifted], halves[:shifted], f.mean_shift_iterations
        )
        particles[:shifted, :2] = window.to_frame(centres[:shifted])
    model = state.model.hist(cfg.features.anchor_weight)
    hists = kernel(planes, centres, halves, cfg)
    weights = particle_likelihood(bhattacharyya(hists, model), f.omega)
    if f.llr_gain > 0:
        weights = weights * llr_factor(lik, centres, halves, cfg)
    kept = np.where(weights >= f.weight_threshold, weights, 0.0)
    if kept.sum() <= 0:
        kept = weights
    candidates = np.stack([weighted_estimate(particles, kept), particles[np.argmax(kept)]])
    cand_centres = window.to_patch(candidates[:, :2])
    cand_hists = kernel(planes, cand_centres, half_size(state.size, candidates[:, 2], window), cfg)
    return planes, kept, candidates, cand_hists, model


def _track(
    state: TrackState, image: Frame, cfg: TrackerConfig, rng: np.random.Generator
) -> tuple[TrackState, TrackResult]:
    """Steps 1-7 (the module's docstring) while the target is tracked."""
    noise = _noise(state, cfg)
    particles = _propagate(state, noise, cfg, rng)
    if cfg.illumination.gain_source == "frame":
        state = replace(state, gain=illumination.from_frame(state.gain, image, cfg.illumination))
    raw = _window(state.size, image, state.estimate, 2.0 * noise, 1.0, cfg)
    window = illumination.compensate(raw, state.gain, cfg.illumination, state.first.cue)
    planes, kept, candidates, cand_hists, model = _weigh(state, window, particles, cfg)
    rhos = bhattacharyya(cand_hists, model)
    best = int(np.argmax(rhos))
    particles = particles[systematic_resample(kept, rng)]
    at, hist, rho = candidates[best], cand_hists[best], float(rhos[best])
    image_f32 = as_float(raw.patch, state.first.cue == "grayscale")
    score, size = -1.0, state.size
    if cfg.refine.template_refine:
        at, particles, size, score = _refined(state, image, image_f32, raw, at, particles, cfg)
        hist = kernel(planes, window.to_patch(at[None, :2]), half_size(size, at[2], window), cfg)[0]
        rho = float(bhattacharyya(hist[None], model)[0])
    features = state.model.features
    state, result = _accept(state, (particles, size), window, (at, hist, rho, score), cfg)
    if result.box is not None and result.confidence >= cfg.lost.lost_below_confidence:
        # the box's histogram under the current gain (window compensated, same features)
        known = hist if window is not raw and features == state.model.features else None
        state = _learn(state, (image, image_f32), raw, at, score, known, cfg)
    return state, result


def _learn(
    state: TrackState,
    images: tuple[Frame, npt.NDArray[np.float32]],
    raw: Window,
    at: FloatArray,
    score: float,
    known: FloatArray | None,
    cfg: TrackerConfig,
) -> TrackState:
    """After a trusted frame: the gain; where the template located the target,
    :meth:`Refiner.learn` (which templates and whether the size filters learn)."""
    half = half_size(state.size, at[2], raw)[0]
    if cfg.illumination.gain_source == "target":
        gain = illumination.from_target(
            state.gain, raw, at[:2], half, state.model, known, cfg, state.first.cue
        )
        if gain is not state.gain:
            state = replace(state, gain=gain)
    if score >= cfg.refine.template_accept_score:
        frame, image_f32 = images
        box = (raw.to_patch(at[:2]), 2.0 * half)
        in_frame = (at[:2], np.array(state.size) * at[2])
        state.refiner.learn(image_f32, box, frame, in_frame, score)
    return state


def _refined(
    state: TrackState,
    image: Frame,
    image_f32: npt.NDArray[np.float32],
    raw: Window,
    at: FloatArray,
    particles: FloatArray,
    cfg: TrackerConfig,
) -> tuple[FloatArray, FloatArray, tuple[float, float], float]:
    """Step 6: the filter's estimate refined on the template, fed back to the particles.

    Returns the estimate, the particles, the box size at scale 1 and the template score (-1
    when the refinement is not used).  It is used when the template matches (``score >=
    template_accept_score``), with its aspect step (width x f, height / f, area kept);
    otherwise the filter's position stands, at the last scale (the histograms cannot tell
    scales apart, and the filter's scale wanders).  A veto by the histograms (the refined
    box's confidence at most 0.1 below the filter's) was tried: with the colour template it
    changed nothing on Crossing and Coke, cost Tiger1 0.03 AUC and sent Car4 off (0.87 ->
    0.28: grey histograms are too weak to judge the template).
    """
    refined, score, aspect = _refine(state, image, image_f32, raw, at, cfg)
    size = state.size
    if score < cfg.refine.template_accept_score:
        refined = np.array([at[0], at[1], state.estimate[2]])
        score = -1.0
    else:
        size = (size[0] * aspect, size[1] / aspect)
    particles[:, :2] += refined[:2] - at[:2]
    particles[:, 2] *= refined[2] / at[2]
    return refined, particles, size, score


def _refine(
    state: TrackState,
    image: Frame,
    image_f32: npt.NDArray[np.float32],
    raw: Window,
    at: FloatArray,
    cfg: TrackerConfig,
) -> tuple[FloatArray, float, float]:
    """The estimate refined on the template: (x, y, scale), the NCC score and the aspect
    step (width x f, height / f).

    The template is searched around the filter's centre (and the last centre, see
    :meth:`Refiner.locate`); at the position found the size filters give the change of
    width and height: the scale is their geometric mean.
    """
    r = cfg.refine
    last = state.estimate
    box = 2.0 * half_size(state.size, last[2], raw)[0]
    found = state.refiner.locate(image_f32, raw.to_patch(np.stack([at[:2], last[:2]])), box)
    xy = raw.to_frame(found.centre[None])[0]
    if found.score < r.template_accept_score:  # not located: the caller keeps the size
        return np.array([xy[0], xy[1], last[2]]), found.score, 1.0
    if state.refiner.slow_score < r.scale_read_score:  # size unreliable: keep it
        return np.array([xy[0], xy[1], last[2]]), found.score, 1.0
    change = state.refiner.size_change(image, xy, np.array(state.size) * last[2])
    aspect = float(np.sqrt(change[0] / change[1]))
    scale = last[2] * float(np.sqrt(change[0] * change[1]))
    scale = min(max(scale, cfg.motion.min_scale), cfg.motion.max_scale)
    return np.array([xy[0], xy[1], scale]), found.score, aspect


def _accept(
    state: TrackState,
    moved: tuple[FloatArray, tuple[float, float]],
    window: Window,
    found: tuple[FloatArray, FloatArray, float, float],
    cfg: TrackerConfig,
) -> tuple[TrackState, TrackResult]:
    """Step 7, commit an estimate: model update, re-ranking, lost bookkeeping.

    ``moved`` are this frame's particles and box size at scale 1, ``found`` the estimate
    (x, y, s), its kernel histogram, its ``rho`` and the template's score.

    A frame counts towards "lost" only if the histograms say so and the template did not
    locate the target (``score`` below ``template_accept_score``).  The reported
    confidence is the histograms' or, when the template located the target, its NCC
    score if that is higher (grey targets: the histograms separate them poorly).
    """
    f, lost = cfg.features, cfg.lost
    (particles, size), (at, hist, rho, score) = moved, found
    confidence = float(state.model.confidence(np.array([rho]))[0])
    located = score >= cfg.refine.template_accept_score
    low = confidence < lost.lost_below_confidence and not located
    low_frames = state.low_frames + 1 if low else 0
    if low_frames >= lost.lost_after_frames:
        state = replace(state, particles=particles, size=size, low_frames=low_frames, lost_frames=1)
        return state, _result(state, None, confidence, cfg)
    reported = max(confidence, score) if located else confidence
    estimate = _inside(state.shape, at)
    history = _pushed(state.history, estimate, cfg)
    model = state.model
    if confidence >= f.rerank_below_confidence:
        model = model.learnt(hist, f.model_update_rate)
    since_rank = state.since_rank + 1
    low = confidence < f.rerank_below_confidence and since_rank >= 3
    due = since_rank >= f.rerank_every_frames or low
    # never below lost_below_confidence: features chosen against a ring around a box the
    # target has left make that background look like the target
    if due and confidence >= lost.lost_below_confidence:
        centre = window.to_patch(estimate[None, :2])[0]
        half = half_size(size, estimate[2], window)[0]
        first_half = half_size(size, 1.0, state.first.window)
        model, _ = rank(window, centre, half, state.first, first_half, not low, cfg)
        since_rank = 0
    state = replace(
        state,
        particles=particles,
        size=size,
        estimate=estimate,
        history=history,
        model=model,
        since_rank=since_rank,
        low_frames=low_frames,
    )
    return state, _result(state, box_of(state, estimate), reported, cfg)


def _search_lost(
    state: TrackState, image: Frame, cfg: TrackerConfig, rng: np.random.Generator
) -> tuple[TrackState, TrackResult]:
    """While lost: a widening window searched for the target; the template must agree
    (histograms alone re-acquire clutter)."""
    widen = cfg.lost.reacquire_growth**state.lost_frames
    state = replace(state, lost_frames=state.lost_frames + 1)
    raw = _window(state.size, image, state.estimate, 0.0, widen, cfg)
    window = illumination.compensate(raw, state.gain, cfg.illumination, state.first.cue)
    xy, confidence = _best_in_window(state, window, cfg, rng)
    if confidence < cfg.lost.reacquire_confidence:
        return state, _result(state, None, confidence, cfg)
    at = np.array([xy[0], xy[1], state.estimate[2]])
    if cfg.refine.template_refine:
        patch = as_float(window.patch, state.first.cue == "grayscale")
        at, score, _ = _refine(state, image, patch, window, at, cfg)
        if score < cfg.refine.template_accept_score:
            return state, _result(state, None, confidence, cfg)
    estimate = _inside(state.shape, at)
    state = replace(
        state,
        estimate=estimate,
        particles=np.tile(estimate, (cfg.filter.particles, 1)),
        history=((estimate[0], estimate[1]),),
        lost_frames=0,
        low_frames=0,
    )
    return state, _result(state, box_of(state, estimate), confidence, cfg)


def _best_in_window(
    state: TrackState, window: Window, cfg: TrackerConfig, rng: np.random.Generator
) -> tuple[FloatArray, float]:
    """The best box in the window (frame pixels) and its confidence: the mode of the
    likelihood image smoothed by the box, plus scattered samples, all mean-shifted."""
    planes, lik = likelihood(window.patch, state.model, cfg)
    half = half_size(state.size, state.estimate[2], window)[0]
    positive = np.maximum(lik, 0.0)
    h, w = positive.shape  # the kernel within the window (a runaway scale: bad_alloc)
    ksize = (int(np.clip(2 * half[0], 1, w)), int(np.clip(2 * half[1], 1, h)))
    smooth = cv2.boxFilter(positive, -1, ksize)
    iy, ix = np.unravel_index(int(np.argmax(smooth)), smooth.shape)
    scatter = rng.random((cfg.filter.particles - 1, 2)) * np.array([w, h])
    centres = np.vstack([[ix + 0.5, iy + 0.5], scatter])
    halves = np.repeat(half[None], len(centres), axis=0)
    centres = mean_shift(
        integral_images(positive), centres, halves, cfg.filter.mean_shift_iterations
    )
    hists = kernel(planes, centres, halves, cfg)
    rhos = bhattacharyya(hists, state.model.hist(cfg.features.anchor_weight))
    best = int(np.argmax(rhos))
    confidence = float(state.model.confidence(rhos[best : best + 1])[0])
    return window.to_frame(centres[best]), confidence
