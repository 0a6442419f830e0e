"""The target's template and size filters: the refinement stage of the adaptive tracker.

The particle filter (colour histograms, mean shift) finds the target to a fraction of its size;
this stage then locates it to a pixel on a template (:mod:`tracker.template`) and reads its
change of width and height with two one-dimensional correlation filters
(:mod:`tracker.scale_filter`).  :class:`Refiner` holds that state for one target; the
:func:`tracker.step.step` decides when its answers are used and when it learns.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tracker.config import RefineConfig
from tracker.scale_filter import (
    ScaleFilter,
    factor_pairs,
    grey_region,
    sample_size,
    samples,
)
from tracker.template import Match, crop, match, ncc, template_size

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]
Frame = npt.NDArray[np.uint8]
Patch = npt.NDArray[np.float32]


@dataclass(frozen=True)
class _Sizer:
    """One size filter with its (width, height) factor pairs."""

    factors: FloatArray
    model: ScaleFilter


class Refiner:
    """Templates (the first frame's mixed with a fast or a slow running one) and size filters.

    ``patch`` is the float32 search window, ``centre``/``box`` on it in patch pixels;
    ``frame``, ``xy``/``box_px`` in full-resolution pixels.  :meth:`locate`,
    :meth:`size_change` and :meth:`learn` change the object; :meth:`fork` gives the copy a
    step advances, so that the state it came from stays as it was.
    """

    def __init__(
        self,
        config: RefineConfig,
        patch: Patch,
        centre: FloatArray,
        box: FloatArray,
        frame: Frame,
        xy: FloatArray,
        box_px: FloatArray,
    ) -> None:
        self.config = config
        self._size = template_size(box)
        self._first = crop(patch, centre, box, self._size)
        self._current = self._first.copy()  # slow: learns where it matches closely
        self._fast = self._first.copy()  # fast: learns on more frames, locates the centre
        self._shape = sample_size(box_px)
        count, step = config.scale_filter_scales, config.scale_filter_step
        steps = [factor_pairs(count, step, kind) for kind in config.size_filters.split("+")]
        self._factors = np.vstack(steps)  # every filter's rows, sampled together
        self._reach = self._factors.max(axis=0)
        rows = self._rows(frame, xy, box_px)
        self._sizers = [
            _Sizer(f, ScaleFilter.train(part)) for f, part in zip(steps, rows, strict=True)
        ]
        self._read: tuple[FloatArray, FloatArray, list[ComplexArray]] | None = None
        self.rival = -1.0
        self.jumped = False  # the target moved further than template_jump_frac since the last
        self.slow_score = 1.0  # the slow template's NCC where :meth:`locate` found the target

    def fork(self) -> Refiner:
        """A copy that learns apart from this one (cheap: every update rebinds its arrays,
        none writes into them, so the arrays are shared until then)."""
        twin = copy.copy(self)
        twin._sizers = [_Sizer(s.factors, s.model.fork()) for s in self._sizers]
        return twin

    def _rows(self, frame: Frame, xy: FloatArray, box_px: FloatArray) -> list[FloatArray]:
        """Each size filter's rows for the box ``box_px`` at ``xy`` (one resampling for all).

        The filters all look at the same box (the width filter at widths ``a**n`` x the box's
        height, the height filter the other way), so their answers multiply.
        """
        region = grey_region(frame, xy, box_px * self._reach / 2.0 + 2.0)
        rows = samples(region, xy, box_px, self._factors, self._shape)
        count = self.config.scale_filter_scales
        return [rows[i : i + count] for i in range(0, len(rows), count)]

    def template(self, running: Patch | None = None) -> Patch:
        """``template_anchor`` x the first frame's template + the rest x a running one (by
        default the fast one, which locates the target)."""
        a = self.config.template_anchor
        rest = self._fast if running is None else running
        return np.asarray(a * self._first + (1.0 - a) * rest, dtype=np.float32)

    def locate(self, patch: Patch, centres: FloatArray, box: FloatArray) -> Match:
        """The fast template's best match around ``centres[0]`` (the filter's estimate), or
        the slow template's where the fast one matches worse than it.

        If the filter moved further than the search reaches (``template_search_frac`` of the
        box) from ``centres[1]`` (the last estimate), the template is looked for there too.
        Where the fast template scores below ``template_update_score`` the slow one is
        searched as well, and where it matches better it locates the target and the fast
        template restarts from it: a fast template that followed a shadow's edge (Car4
        leaving the bridge's shadow) loses the car when the light comes back, and the slow
        one, which never learnt the shadow, finds it.
        """
        found = self._search(patch, centres, box, self.template())
        self.slow_score = ncc(
            crop(patch, found.centre, box, self._size), self.template(self._current)
        )
        if found.score < self.config.template_update_score:
            slow = self._search(patch, centres, box, self.template(self._current))
            if slow.score > found.score:
                found, self._fast = slow, self._current.copy()
                self.slow_score = slow.score
        self.rival = found.rival
        self.jumped = bool(
            np.any(np.abs(found.centre - centres[1]) > self.config.template_jump_frac * box)
        )
        return found

    def _search(self, patch: Patch, centres: FloatArray, box: FloatArray, template: Patch) -> Match:
        """``template``'s best match near the filter's estimate or the last one (ambiguous
        peaks: :meth:`_nearer_if_ambiguous`)."""
        frac = self.config.template_search_frac
        found = match(patch, template, centres[0], box, frac, ((1.0, 1.0),))
        if np.any(np.abs(centres[1] - centres[0]) > frac * box):
            last = match(patch, template, centres[1], box, frac, ((1.0, 1.0),))
            found = last if last.score > found.score else found
        return self._nearer_if_ambiguous(found, centres[1])

    def _nearer_if_ambiguous(self, found: Match, last: FloatArray) -> Match:
        """Where a rival peak scores within ``template_rival_margin`` of the best, the one
        nearer the last estimate (a look-alike passing by); ``rival`` then marks the frame
        ambiguous (the fast template does not learn it)."""
        margin = self.config.template_rival_margin
        if found.rival_centre is None or found.rival < found.score - margin:
            return found
        near = np.hypot(*(found.rival_centre - last)) < np.hypot(*(found.centre - last))
        if not near:
            return found
        return Match(found.rival_centre, found.scale, found.rival, found.score, found.centre)

    def size_change(self, frame: Frame, xy: FloatArray, box_px: FloatArray) -> FloatArray:
        """(width, height) factors of the box at ``xy``: the product of the filters' peaks."""
        change = np.ones(2)
        spectra = self._spectra(frame, xy, box_px)
        for sizer, z in zip(self._sizers, spectra, strict=True):
            change = change * sizer.factors[sizer.model.peak(z) + len(sizer.factors) // 2]
        self._read = (xy.copy(), box_px.copy(), spectra)
        return change

    def _spectra(self, frame: Frame, xy: FloatArray, box_px: FloatArray) -> list[ComplexArray]:
        """Each size filter's spectrum of its rows for the box ``box_px`` at ``xy``."""
        rows = self._rows(frame, xy, box_px)
        return [s.model.spectrum(r) for s, r in zip(self._sizers, rows, strict=True)]

    def learn(
        self,
        patch: Patch,
        box_on_patch: tuple[FloatArray, FloatArray],
        frame: Frame,
        box_in_frame: tuple[FloatArray, FloatArray],
        score: float,
    ) -> None:
        """Learn the box given (centre, size) on a frame where the template matched at ``score``.

        Two running templates: the fast one (which locates the target) learns where ``score >=
        template_update_score``; the slow one and the size filters only where the slow
        template matches the box at ``scale_update_score`` or better.  A template that learns
        on many frames follows a slow change of appearance (Coke's turning can) but also a
        shadow's edge creeping over the target (Car4 under the bridge): it then matches the lit
        half at NCC 0.9, and size filters learning from those frames shrank the box to half its
        height.  The slow template does not follow the shadow, so it keeps the size filters
        off those frames.
        """
        cfg = self.config
        centre, box = box_on_patch
        fresh = crop(patch, centre, box, self._size)
        rate = cfg.template_update_rate
        clear = self.rival < score - cfg.template_rival_margin and not self.jumped
        if score >= cfg.template_update_score and clear:
            self._fast = (1.0 - rate) * self._fast + rate * fresh
        if self.slow_score < cfg.scale_update_score:
            return
        self._current = (1.0 - rate) * self._current + rate * fresh
        xy, box_px = box_in_frame
        read = self._read
        if read is not None and bool(np.all(read[0] == xy) and np.all(read[1] == box_px)):
            spectra = read[2]  # the box the filters just read (no size change): same rows
        else:
            spectra = self._spectra(frame, xy, box_px)
        for sizer, f in zip(self._sizers, spectra, strict=True):
            sizer.model.update(f, self.config.scale_filter_rate)
