"""The adaptive landmark tracker: online feature selection + mean-shift-embedded particle filter.

Per frame (paper sec. 3-4): propagate the particles with adaptive noise (eq. 1); cut a search
window around the last estimate and compute only the selected features there; back-project the
log-likelihood ratio of each feature (eq. 8) into a likelihood image (fig. 5); move one set of
particles by mean shift on that image and leave the other set where it is; weight every particle
by ``exp(-omega s^2)`` from the Bhattacharyya distance of its Epanechnikov-weighted histograms
(eq. 2-4); drop particles below ``weight_threshold``; estimate; resample systematically.
Features are re-ranked by variance ratio (eq. 6-7) every ``rerank_every_frames`` frames and when
the confidence drops, with the object histograms anchored to the first frame's.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from tracker.appearance import (
    bhattacharyya,
    histograms_from_samples,
    joint_planes,
    particle_likelihood,
    sample_bins,
)
from tracker.config import TrackerConfig, check_config
from tracker.features import GRAY_FEATURES, colour_weights, feature_bins, is_grayscale
from tracker.particles import (
    integral_images,
    mean_shift,
    motion_noise,
    propagate,
    systematic_resample,
    weighted_estimate,
    window_sums,
)
from tracker.ranking import log_likelihood_ratio, masked_histograms, rank_features, ring_masks
from tracker.refine import Refiner
from tracker.template import as_float
from tracker.types import Box, Cue, TrackResult
from tracker.validation import check_box, check_image, check_same_frame
from tracker.window import Window, clamp_index, cut_window, frame_mean, work_factor

FloatArray = npt.NDArray[np.float64]
_NEIGHBOURS = np.array([(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy], float)


@dataclass
class _Model:
    """The appearance model for the selected features."""

    features: tuple[int, ...]
    llr: FloatArray  # (k, bins) log-likelihood ratio, eq. 8
    first: FloatArray  # (k, bins) kernel histograms on the first frame
    recent: FloatArray  # (k, bins) running kernel histograms of recent estimates
    rho_ref: float  # rho of the first frame's target against the model
    rho_bg: float  # mean rho of the background around the target against the model


class AdaptiveTracker:
    """Track one target; ``init`` on the first frame, then ``update`` on each next frame."""

    name = "adaptive"

    def __init__(self, config: TrackerConfig | None = None, seed: int = 0) -> None:
        self.config = config if config is not None else TrackerConfig()
        check_config(self.config)
        self.rng = np.random.default_rng(seed)
        self._shape: tuple[int, ...] | None = None

    # ------------------------------------------------------------------ public API
    def init(self, image_bgr: npt.NDArray[np.uint8], box: Box, rank_phase: int = 0) -> None:
        """Start tracking the target inside ``box`` = (x, y, w, h) of the first frame.

        ``rank_phase`` shifts the periodic re-ranking by that many frames: trackers started
        together with different phases do not all re-rank on the same frame (a caller
        tracking several targets in real time keeps its per-frame cost even).
        """
        image = check_image(image_bgr)
        x, y, w, h = check_box(box, image.shape)
        cfg = self.config
        self._shape = image.shape
        self._size0 = (w, h)
        self._state = np.array([x + w / 2.0, y + h / 2.0, 1.0])
        window = self._window(image, self._state, 0.0, 1.0)
        self._cue: Cue = (
            "grayscale" if is_grayscale(window.patch, cfg.features.gray_tolerance) else "colour"
        )
        self._candidates = GRAY_FEATURES if self._cue == "grayscale" else tuple(range(49))
        self._first = (window, self._state.copy())
        self._refiner = Refiner(
            cfg.refine,
            as_float(window.patch, self._cue == "grayscale"),
            window.to_patch(self._state[:2]),
            2.0 * self._half(1.0, window)[0],
            image,
            self._state[:2],
            np.array(self._size0),
        )
        self._aspect_step = 1.0
        self._ref_mean = self._box_mean(window, self._state)
        self._ref_frame_mean = frame_mean(image)
        self._gain = np.ones(3)
        self._p_first: FloatArray | None = None
        self._model = self._rank(window, self._state)
        self._particles = np.tile(self._state, (cfg.filter.particles, 1))
        self._history: list[tuple[float, float]] = [(self._state[0], self._state[1])]
        self._since_rank = rank_phase % cfg.features.rerank_every_frames
        self._low_frames = 0
        self._lost_frames = 0

    @property
    def features(self) -> tuple[int, ...]:
        """Ids of the features in use (best first)."""
        return self._model.features

    @property
    def particle_centres(self) -> FloatArray:
        """(N, 2) image positions (x, y) of the particle set after the last update."""
        return np.asarray(self._particles[:, :2], dtype=np.float64).copy()

    @property
    def cue(self) -> Cue:
        """``"colour"`` or ``"grayscale"`` (the grey features and the template, no colour)."""
        return self._cue

    def update(self, image_bgr: npt.NDArray[np.uint8]) -> TrackResult:
        """Track into the next frame; ``box`` is None while the target is lost."""
        if self._shape is None:
            raise ValueError("update: call init(image_bgr, box) first")
        check_same_frame(image_bgr, self._shape)
        if self._lost_frames > 0:
            return self._search_lost(image_bgr)
        return self._track(image_bgr)

    def likelihood_images(
        self, image_bgr: npt.NDArray[np.uint8]
    ) -> list[tuple[int, npt.NDArray[np.float32]]]:
        """The log-likelihood ratio of each selected feature back-projected on a whole frame.

        For reports and inspection only (fig. 5); tracking never computes whole-frame features.
        """
        image = check_image(image_bgr)
        planes = feature_bins(
            image,
            self._model.features,
            self.config.features.bins,
            self.config.features.stretch_features,
        )
        return [
            (fid, self._model.llr[i][planes[i]].astype(np.float32))
            for i, fid in enumerate(self._model.features)
        ]

    # ------------------------------------------------------------------ internals
    def _half(self, scale: FloatArray | float, window: Window) -> FloatArray:
        """Half box sizes in patch pixels for one or more scales -> (P, 2)."""
        w0, h0 = self._size0
        half = np.array([w0 * window.fx / 2.0, h0 * window.fy / 2.0])
        return np.multiply.outer(np.atleast_1d(np.asarray(scale, dtype=np.float64)), half)

    def _window(
        self, image: npt.NDArray[np.uint8], state: FloatArray, extra_px: float, widen: float
    ) -> Window:
        w, h = self._size0[0] * state[2], self._size0[1] * state[2]
        grow = (0.5 + self.config.filter.search_margin_frac) * widen
        extent = (w * grow + extra_px, h * grow + extra_px)
        factor = work_factor(w, h, self.config.filter.work_area_px)
        return cut_window(image, (state[0], state[1]), extent, factor)

    def _box_mean(self, window: Window, state: FloatArray) -> FloatArray:
        """Mean BGR of the central part (``gain_core_frac`` of the size) of the box ``state``."""
        c = window.to_patch(state[None, :2])[0]
        half = self._half(state[2], window)[0] * self.config.illumination.gain_core_frac
        h, w = window.patch.shape[:2]
        x0, x1 = clamp_index(c[0] - half[0], 0, w - 1), clamp_index(c[0] + half[0], 1, w)
        y0, y1 = clamp_index(c[1] - half[1], 0, h - 1), clamp_index(c[1] + half[1], 1, h)
        region = window.patch[y0 : max(y1, y0 + 1), x0 : max(x1, x0 + 1)]
        return np.maximum(np.asarray(cv2.mean(region)[:3], dtype=np.float64), 1.0)

    def _compensated(self, window: Window) -> Window:
        """The window with the illumination gain removed (per channel, clipped to 0..255)."""
        gain = self._effective_gain(self._gain).astype(np.float32)
        if not self._gain_applies() or np.abs(gain - 1.0).max() < 0.01:
            return window
        patch = np.clip(window.patch * gain, 0, 255).astype(np.uint8)
        return Window(window.x0, window.y0, window.fx, window.fy, patch)

    def _gain_applies(self) -> bool:
        mode = self.config.illumination.gain_compensation
        return mode == "always" or (mode == "colour" and self._cue == "colour")

    def _effective_gain(self, gain: FloatArray) -> FloatArray:
        """The gain applied: a dead band (``gain_deadband``) keeps small drifts uncorrected."""
        band = self.config.illumination.gain_deadband
        return 1.0 + np.sign(gain - 1.0) * np.maximum(np.abs(gain - 1.0) - band, 0.0)

    def _frame_gain(self, image: npt.NDArray[np.uint8]) -> None:
        """gain <- (1-r) gain + r * (first frame's mean / this frame's mean), on a 1/8 grid."""
        ratio = self._ref_frame_mean / frame_mean(image)
        if self.config.illumination.gain_mode == "grey":
            ratio = np.full(3, float(self._ref_frame_mean.sum() / frame_mean(image).sum()))
        rate = self.config.illumination.gain_rate
        self._gain = (1.0 - rate) * self._gain + rate * np.clip(ratio, 0.25, 4.0)

    def _update_gain(self, raw: Window, state: FloatArray, known: FloatArray | None) -> None:
        """gain <- (1-r) gain + r * (first-frame target mean / current target mean).

        With ``gain_check`` the new gain is kept only if the target box, compensated with it,
        looks at least as much like the model as with the old gain (``known``: its histogram).
        """
        current = self._box_mean(raw, state)
        ratio = np.clip(self._ref_mean / current, 0.25, 4.0)
        if self.config.illumination.gain_mode == "grey":
            ratio = np.full(3, min(max(float(self._ref_mean.sum() / current.sum()), 0.25), 4.0))
        rate = self.config.illumination.gain_rate
        proposed = (1.0 - rate) * self._gain + rate * ratio
        if self.config.illumination.gain_check and self._gain_applies():
            if known is None:
                now = self._rho_under_gains(raw, state, self._gain[None])
            else:
                now = bhattacharyya(known[None], self._model_hist())
            if self._rho_under_gains(raw, state, proposed[None])[0] < now[0]:
                return
        self._gain = proposed

    def _rho_under_gains(self, raw: Window, state: FloatArray, gains: FloatArray) -> FloatArray:
        """Bhattacharyya ``rho`` of the box ``state`` against the model, per gain (G, 3)."""
        cfg = self.config
        centre = raw.to_patch(state[None, :2])
        channels = np.moveaxis(raw.patch, 2, 0).astype(np.intp)
        pixels = sample_bins(channels, centre, self._half(state[2], raw), cfg.filter.sample_grid)[
            :, 0
        ].T
        effective = np.stack([self._effective_gain(g) for g in gains])
        lit = np.clip(pixels[None] * effective[:, None, :], 0, 255).astype(np.uint8)
        planes = feature_bins(
            lit, self._model.features, cfg.features.bins, cfg.features.stretch_features
        )
        return bhattacharyya(self._sample_histograms(planes), self._model_hist())

    def _likelihood(self, window: Window) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.float32]]:
        """Bin images of the selected features and their mean back-projected LLR image."""
        planes = feature_bins(
            window.patch,
            self._model.features,
            self.config.features.bins,
            self.config.features.stretch_features,
        )
        llr = self._model.llr
        image = llr[0][planes[0]]
        for i in range(1, len(planes)):
            image = image + llr[i][planes[i]]
        return planes, (image / len(planes)).astype(np.float32)

    def _rank(self, window: Window, state: FloatArray, trusted: bool = True) -> _Model:
        """Select the top features by variance ratio (eq. 6-8) and rebuild the model.

        The object histograms mix the first frame's with the current estimate's
        (``anchor_weight``); when the estimate is not ``trusted`` (low confidence) only the
        first frame's are used, so a drifting estimate cannot redefine the target.
        """
        cfg = self.config
        centre = window.to_patch(state[None, :2])[0]
        half = self._half(state[2], window)[0]
        patch_box = (centre[0] - half[0], centre[1] - half[1], 2 * half[0], 2 * half[1])
        inner, ring = ring_masks(window.patch.shape[:2], patch_box, cfg.features.ring_area_ratio)
        if (
            self._cue == "colour" and not cfg.features.stretch_features
        ):  # per pixel: box and ring only
            used = inner | ring
            inner, ring = inner[used][None], ring[used][None]
            planes = feature_bins(window.patch[used][None], self._candidates, cfg.features.bins)
        else:  # the grey features are neighbourhood operators: the whole window
            planes = feature_bins(
                window.patch, self._candidates, cfg.features.bins, cfg.features.stretch_features
            )
        p_now = masked_histograms(planes, inner, cfg.features.bins)
        q = masked_histograms(planes, ring, cfg.features.bins)
        if self._p_first is None:
            self._p_first = p_now
        anchor = cfg.features.anchor_weight if trusted else 1.0
        p = anchor * self._p_first + (1.0 - anchor) * p_now
        directions = colour_weights().astype(np.float64) if self._cue == "colour" else None
        top, _ = rank_features(
            p,
            q,
            self._candidates,
            cfg.features.loglik_floor,
            cfg.features.top_features,
            directions,
            cfg.features.max_feature_cosine,
        )
        rows = [self._candidates.index(f) for f in top]
        llr = log_likelihood_ratio(p[rows], q[rows], cfg.features.loglik_floor)
        first_window, first_state = self._first
        first = self._hist(first_window, first_state[None], top)[0]
        sel = feature_bins(window.patch, top, cfg.features.bins, cfg.features.stretch_features)
        recent = self._kernel(sel, centre[None], half[None])[0] if trusted else first
        model = cfg.features.anchor_weight * first + (1.0 - cfg.features.anchor_weight) * recent
        around = centre[None] + _NEIGHBOURS * 2.0 * half[None]
        halves = np.repeat(half[None], len(around), axis=0)
        bg = self._kernel(sel, around, halves)
        rho_bg = float(bhattacharyya(bg, model).mean())
        rho_ref = float(bhattacharyya(first[None], model)[0])
        return _Model(top, llr, first, recent, rho_ref, min(rho_bg, rho_ref - 0.05))

    def _hist(self, window: Window, states: FloatArray, ids: tuple[int, ...]) -> FloatArray:
        planes = feature_bins(
            window.patch, ids, self.config.features.bins, self.config.features.stretch_features
        )
        centres = window.to_patch(states[:, :2])
        return self._kernel(planes, centres, self._half(states[:, 2], window))

    def _kernel(
        self, planes: npt.NDArray[np.intp], centres: FloatArray, halves: FloatArray
    ) -> FloatArray:
        """Kernel histograms (eq. 2) of the appearance model: joint or per-feature."""
        samples = sample_bins(planes, centres, halves, self.config.filter.sample_grid)
        return self._sample_histograms(samples)

    def _sample_histograms(self, samples: npt.NDArray[np.intp]) -> FloatArray:
        """Kernel histograms from bins sampled on the kernel grid, (k, P, m) -> (P, ...)."""
        cfg = self.config
        if cfg.features.appearance == "joint":
            joint = joint_planes(samples, cfg.features.bins, cfg.features.joint_bins)
            nbins = cfg.features.joint_bins ** samples.shape[0]
            return histograms_from_samples(joint, cfg.filter.sample_grid, nbins)
        return histograms_from_samples(samples, cfg.filter.sample_grid, cfg.features.bins)

    def _confidence(self, rho: FloatArray) -> FloatArray:
        """Calibrated confidence: 0 at the background's similarity, 1 at the first frame's."""
        m = self._model
        return np.minimum(np.maximum((rho - m.rho_bg) / (m.rho_ref - m.rho_bg), 0.0), 1.0)

    def _model_hist(self) -> FloatArray:
        a = self.config.features.anchor_weight
        return a * self._model.first + (1.0 - a) * self._model.recent

    def _noise(self) -> float:
        cfg = self.config
        side = 0.5 * (self._size0[0] + self._size0[1]) * self._state[2]
        return motion_noise(
            self._history,
            cfg.motion.motion_history_frames,
            cfg.motion.motion_gain,
            cfg.motion.motion_min_frac * side,
            cfg.motion.motion_max_frac * side,
            cfg.motion.motion_initial_frac * side,
        )

    def _track(self, image: npt.NDArray[np.uint8]) -> TrackResult:
        cfg = self.config
        noise = self._noise()
        scale_range = (cfg.motion.min_scale, cfg.motion.max_scale)
        particles = propagate(self._particles, noise, cfg.motion.scale_noise, scale_range, self.rng)
        if (
            cfg.motion.drift_gain > 0 and len(self._history) >= 2
        ):  # CONDENSATION drift: mean velocity
            steps = np.diff(np.asarray(self._history), axis=0)
            particles[:, :2] += cfg.motion.drift_gain * steps.mean(axis=0)
        if cfg.illumination.gain_source == "frame":
            self._frame_gain(image)
        raw = self._window(image, self._state, 2.0 * noise, 1.0)
        window = self._compensated(raw)
        planes, lik = self._likelihood(window)
        centres = window.to_patch(particles[:, :2])
        halves = self._half(particles[:, 2], window)
        shifted = round(cfg.filter.particles * cfg.filter.mean_shift_fraction)
        tables = integral_images(np.maximum(lik, 0.0))
        if shifted and cfg.filter.mean_shift_iterations:
            centres[:shifted] = mean_shift(
                tables, centres[:shifted], halves[:shifted], cfg.filter.mean_shift_iterations
            )
            particles[:shifted, :2] = window.to_frame(centres[:shifted])
        model = self._model_hist()
        hists = self._kernel(planes, centres, halves)
        weights = particle_likelihood(bhattacharyya(hists, model), cfg.filter.omega)
        if cfg.filter.llr_gain > 0:
            weights = weights * self._llr_factor(lik, centres, halves)
        kept = np.where(weights >= cfg.filter.weight_threshold, weights, 0.0)
        if kept.sum() <= 0:
            kept = weights
        candidates = np.stack([weighted_estimate(particles, kept), particles[np.argmax(kept)]])
        cand_hists = self._kernel(
            planes, window.to_patch(candidates[:, :2]), self._half(candidates[:, 2], window)
        )
        rhos = bhattacharyya(cand_hists, model)
        best = int(np.argmax(rhos))
        self._particles = particles[systematic_resample(kept, self.rng)]
        state, hist, rho = candidates[best], cand_hists[best], float(rhos[best])
        image_f32 = as_float(raw.patch, self._cue == "grayscale")
        if cfg.refine.template_refine:
            pair = (raw, window)
            state, hist, rho, score = self._refined(image, image_f32, pair, planes, state)
        else:
            score = -1.0
        features = self._model.features
        result = self._accept(window, state, hist, rho, score)
        if result.box is not None and result.confidence >= cfg.lost.lost_below_confidence:
            # the box's histogram under the current gain (window compensated, same features)
            known = hist if window is not raw and features == self._model.features else None
            self._learn((image, image_f32), raw, state, score, known)
        return result

    def _learn(
        self,
        images: tuple[npt.NDArray[np.uint8], npt.NDArray[np.float32]],
        raw: Window,
        state: FloatArray,
        score: float,
        known: FloatArray | None,
    ) -> None:
        """After a trusted frame: the gain; where the template located the target,
        :meth:`Refiner.learn` (which templates and whether the size filters learn)."""
        if self.config.illumination.gain_source == "target":
            self._update_gain(raw, state, known)
        if score >= self.config.refine.template_accept_score:
            frame, image_f32 = images
            box = (raw.to_patch(state[:2]), 2.0 * self._half(state[2], raw)[0])
            in_frame = (state[:2], self._box_px(state))
            self._refiner.learn(image_f32, box, frame, in_frame, score)

    def _refined(
        self,
        image: npt.NDArray[np.uint8],
        image_f32: npt.NDArray[np.float32],
        windows: tuple[Window, Window],
        planes: npt.NDArray[np.intp],
        state: FloatArray,
    ) -> tuple[FloatArray, FloatArray, float, float]:
        """The filter's estimate refined on the template, fed back to the particles.

        ``windows`` are the raw and the gain-compensated window.  Returns the state, its
        kernel histogram, ``rho`` and the template score (-1 when the refinement is not
        used).  It is used when the template matches (``score >= template_accept_score``);
        otherwise the filter's position stands, at the last scale (the histograms cannot
        tell scales apart, and the filter's scale wanders).  A veto by the histograms (the
        refined box's confidence at most 0.1 below the filter's) was tried: with the colour
        template it changed nothing on Crossing and Coke, cost Tiger1 0.03 AUC and sent
        Car4 off (0.87 -> 0.28: grey histograms are too weak to judge the template).
        """
        raw, window = windows
        refined, score = self._refine(image, image_f32, raw, state)
        if score < self.config.refine.template_accept_score:
            refined = np.array([state[0], state[1], self._state[2]])
            score = -1.0
        else:  # aspect: width x f, height / f (area kept)
            w0, h0 = self._size0
            self._size0 = (w0 * self._aspect_step, h0 / self._aspect_step)
        self._particles[:, :2] += refined[:2] - state[:2]
        self._particles[:, 2] *= refined[2] / state[2]
        hist = self._hist_at(planes, window, refined)
        rho = float(bhattacharyya(hist[None], self._model_hist())[0])
        return refined, hist, rho, score

    def _hist_at(
        self, planes: npt.NDArray[np.intp], window: Window, state: FloatArray
    ) -> FloatArray:
        """The kernel histogram of the box ``state``."""
        centre = window.to_patch(state[None, :2])
        return self._kernel(planes, centre, self._half(state[2], window))[0]

    def _refine(
        self,
        image: npt.NDArray[np.uint8],
        image_f32: npt.NDArray[np.float32],
        raw: Window,
        state: FloatArray,
    ) -> tuple[FloatArray, float]:
        """The estimate refined on the template: (x, y, scale) and the NCC score (-1: off).

        The template is searched around the filter's centre (and the last centre, see
        :meth:`Refiner.locate`); at the position found the size filters give the change of
        width and height: the scale is their geometric mean, the aspect step (width x f,
        height / f) is left in ``self._aspect_step``.
        """
        cfg = self.config
        if not cfg.refine.template_refine:
            return state, -1.0
        box = 2.0 * self._half(self._state[2], raw)[0]
        found = self._refiner.locate(
            image_f32, raw.to_patch(np.stack([state[:2], self._state[:2]])), box
        )
        xy = raw.to_frame(found.centre[None])[0]
        if found.score < cfg.refine.template_accept_score:  # not located: the caller keeps the size
            return np.array([xy[0], xy[1], self._state[2]]), found.score
        if self._refiner.slow_score < cfg.refine.scale_read_score:  # size unreliable: keep it
            self._aspect_step = 1.0
            return np.array([xy[0], xy[1], self._state[2]]), found.score
        change = self._refiner.size_change(image, xy, self._box_px(self._state))
        self._aspect_step = float(np.sqrt(change[0] / change[1]))
        scale = self._state[2] * float(np.sqrt(change[0] * change[1]))
        scale = min(max(scale, cfg.motion.min_scale), cfg.motion.max_scale)
        return np.array([xy[0], xy[1], scale]), found.score

    def _box_px(self, state: FloatArray) -> FloatArray:
        """(width, height) of the box ``state`` in full-resolution pixels."""
        return np.array(self._size0) * state[2]

    def _llr_factor(
        self, lik: npt.NDArray[np.float32], centres: FloatArray, halves: FloatArray
    ) -> FloatArray:
        """``exp(gain * (vote - max over particles))``: the likelihood image's vote.

        The vote is the mean LLR in the box minus, with ``llr_vote = "contrast"``, the mean
        LLR in the ring around it (the ranking's ring, ``ring_area_ratio``).  The box mean
        alone favours boxes smaller than the target (its most distinctive pixels); the
        contrast drops both when background enters the box and when target enters the ring.
        """
        vote = self._vote(lik, centres, halves)
        return np.exp(self.config.filter.llr_gain * (vote - vote.max()))

    def _vote(
        self, lik: npt.NDArray[np.float32], centres: FloatArray, halves: FloatArray
    ) -> FloatArray:
        """Mean LLR in each box, minus (``llr_vote = "contrast"``) the mean in its ring."""
        table: FloatArray = np.asarray(cv2.integral(lik, sdepth=cv2.CV_64F), np.float64)[None]
        sums, area = window_sums(table, centres, halves)
        vote = sums[0] / np.maximum(area, 1.0)
        if self.config.filter.llr_vote == "contrast":
            grow = float(np.sqrt(1.0 + self.config.features.ring_area_ratio))
            outer, outer_area = window_sums(table, centres, halves * grow)
            vote = vote - (outer[0] - sums[0]) / np.maximum(outer_area - area, 1.0)
        return vote

    def _accept(
        self, window: Window, state: FloatArray, hist: FloatArray, rho: float, score: float
    ) -> TrackResult:
        """Commit an estimate: model update, re-ranking, lost bookkeeping.

        A frame counts towards "lost" only if the histograms say so and the template did not
        locate the target (``score`` below ``template_accept_score``).  The reported
        confidence is the histograms' or, when the template located the target, its NCC
        score if that is higher (grey targets: the histograms separate them poorly).
        """
        cfg = self.config
        confidence = float(self._confidence(np.array([rho]))[0])
        located = score >= cfg.refine.template_accept_score
        low = confidence < cfg.lost.lost_below_confidence and not located
        self._low_frames = self._low_frames + 1 if low else 0
        if self._low_frames >= cfg.lost.lost_after_frames:
            self._lost_frames = 1
            return self._result(None, confidence)
        reported = max(confidence, score) if located else confidence
        self._state = state = self._inside(state)
        self._history.append((state[0], state[1]))
        del self._history[: -cfg.motion.motion_history_frames - 1]
        if confidence >= cfg.features.rerank_below_confidence:
            rate = cfg.features.model_update_rate
            self._model.recent = (1.0 - rate) * self._model.recent + rate * hist
        self._since_rank += 1
        low = confidence < cfg.features.rerank_below_confidence and self._since_rank >= 3
        due = self._since_rank >= cfg.features.rerank_every_frames or low
        # never below lost_below_confidence: features chosen against a ring around a box the
        # target has left make that background look like the target
        if due and confidence >= cfg.lost.lost_below_confidence:
            self._model = self._rank(window, state, not low)
            self._since_rank = 0
        return self._result(self._box(state), reported)

    def _search_lost(self, image: npt.NDArray[np.uint8]) -> TrackResult:
        """Widening search: mode of the smoothed likelihood plus scattered, mean-shifted samples."""
        cfg = self.config
        widen = cfg.lost.reacquire_growth**self._lost_frames
        self._lost_frames += 1
        window = self._compensated(self._window(image, self._state, 0.0, widen))
        planes, lik = self._likelihood(window)
        half = self._half(self._state[2], window)[0]
        positive = np.maximum(lik, 0.0)
        h, w = positive.shape  # the kernel within the window (a runaway scale: bad_alloc)
        ksize = (int(np.clip(2 * half[0], 1, w)), int(np.clip(2 * half[1], 1, h)))
        smooth = cv2.boxFilter(positive, -1, ksize)
        iy, ix = np.unravel_index(int(np.argmax(smooth)), smooth.shape)
        scatter = self.rng.random((cfg.filter.particles - 1, 2)) * np.array([w, h])
        centres = np.vstack([[ix + 0.5, iy + 0.5], scatter])
        halves = np.repeat(half[None], len(centres), axis=0)
        centres = mean_shift(
            integral_images(positive), centres, halves, cfg.filter.mean_shift_iterations
        )
        hists = self._kernel(planes, centres, halves)
        rhos = bhattacharyya(hists, self._model_hist())
        best = int(np.argmax(rhos))
        confidence = float(self._confidence(rhos[best : best + 1])[0])
        if confidence < cfg.lost.reacquire_confidence:
            return self._result(None, confidence)
        xy = window.to_frame(centres[best])
        state = np.array([xy[0], xy[1], self._state[2]])
        if (
            cfg.refine.template_refine
        ):  # the template must agree: histograms alone re-acquire clutter
            patch = as_float(window.patch, self._cue == "grayscale")
            state, score = self._refine(image, patch, window, state)
            if score < cfg.refine.template_accept_score:
                return self._result(None, confidence)
        self._state = self._inside(state)
        self._particles = np.tile(self._state, (cfg.filter.particles, 1))
        self._history = [(self._state[0], self._state[1])]
        self._lost_frames = 0
        self._low_frames = 0
        return self._result(self._box(self._state), confidence)

    def _inside(self, state: FloatArray) -> FloatArray:
        """The state with its centre clipped to the frame (the target's centre is in view)."""
        assert self._shape is not None
        h, w = self._shape[:2]
        return np.array([min(max(state[0], 0.0), w), min(max(state[1], 0.0), h), state[2]])

    def _box(self, state: FloatArray) -> Box:
        w, h = self._size0[0] * state[2], self._size0[1] * state[2]
        return (float(state[0] - w / 2), float(state[1] - h / 2), float(w), float(h))

    def _result(self, box: Box | None, confidence: float) -> TrackResult:
        return TrackResult(
            box=box,
            confidence=confidence,
            features=self._model.features,
            lost=box is None,
            cue=self._cue,
            particles=self.config.filter.particles,
        )
