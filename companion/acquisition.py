"""When to look for untracked landmarks, and how: the housekeeping half of the perception.

:class:`Acquisition` runs on the pipeline's background lane, once per frame it is given
(``Perception.housekeeping``), and decides which acquirers (:mod:`companion.acquirers`)
run on that frame:

* feature matching now and then (``acquire_every_frames``; ``_with_fix`` while fixes come)
  and at once whenever nothing is tracked or the light stepped (:meth:`Acquisition.run`'s
  ``now``);
* prediction from the frame's fix, whenever there is one, else from the autopilot's own
  pose estimate when it gives one (a plate entering the image while nothing else is in
  view: issue 19);
* without a fix for ``search_after_s``: the detector's hits, and the template search when
  they start nothing.  With tracks running these take turns with feature matching, one
  heavy step per call (docs/benchmarks.md, "Latency tail");
* once nothing has been tracked for ``idle_after_s``: feature matching and the search on
  one frame in ``idle_search_every_frames`` (:meth:`Acquisition.idle_wait`).

It sees the tracks only as the snapshot it is given and returns what it started; the
caller hands that over to the worker thread (:meth:`companion.tracks.TrackSet.hand_over`).
Its own state (the schedule's turns and clocks) is the background lane's alone.
"""

from __future__ import annotations

from companion.acquirers import Acquirer, Sighting, Starter
from companion.perception_types import PerceptionConfig, Start

#: "Never": a frame index or time that makes every interval due.
LONG_AGO = -(2**62)


class Acquisition:
    """The acquirers and their schedule."""

    def __init__(self, config: PerceptionConfig, starter: Starter, features: Acquirer,
                 prediction: Acquirer, search: Acquirer, detector: Acquirer | None) -> None:
        self.config = config
        self.starter = starter
        self.features = features
        self.prediction = prediction
        self.search = search
        self.detector = detector
        self.last_fix_us = LONG_AGO
        self.acquired_frame = LONG_AGO
        self._lost_turn = False  # features (first) and the lost search take turns
        self._search_next = False  # the template search's turn after a fruitless detector
        self.tracked_us = LONG_AGO  # when a track was last seen running
        self.idle_frame = LONG_AGO  # the last idle search's frame

    def due_now(self) -> None:
        """Feature matching is due on the next frame (a light step)."""
        self.acquired_frame = LONG_AGO
        self.idle_frame = LONG_AGO

    def idle_wait(self, index: int, t_us: int, sight: Sighting) -> bool:
        """True when this frame skips feature matching and the search: nothing has been
        tracked for ``idle_after_s`` (nor is waiting), no fix, and the last idle search
        was fewer than ``idle_search_every_frames`` frames ago.  With nothing in view,
        searching back to back kept a core busy (issue 23); a track just lost is looked
        for at the full rate until ``idle_after_s``."""
        cfg = self.config
        if sight.seen.busy() or sight.fix is not None:
            self.tracked_us = t_us
            return False
        if t_us - self.tracked_us <= cfg.idle_after_s * 1e6:
            return False
        if index - self.idle_frame < cfg.idle_search_every_frames:
            return True
        self.idle_frame = index
        return False

    def should_acquire(self, index: int, t_us: int, sight: Sighting) -> bool:
        """Feature matching is due: nothing tracked, or ``acquire_every_frames`` since the
        last (``acquire_every_frames_with_fix`` while fixes come: prediction then finds the
        plates in view, at a fraction of SIFT's cost)."""
        cfg = self.config
        if sight.seen.busy() >= cfg.max_tracks:
            return False
        recent_fix = t_us - self.last_fix_us <= cfg.search_after_s * 1e6
        every = cfg.acquire_every_frames_with_fix if recent_fix else cfg.acquire_every_frames
        return not sight.seen.tracked or index - self.acquired_frame >= every

    def run(self, index: int, t_us: int, sight: Sighting) -> list[Start]:
        """What this frame's housekeeping starts (frame ``index`` captured at ``t_us``)."""
        starts: list[Start] = []
        if sight.fix is not None:
            self.last_fix_us = sight.fix.time_us
        idle = self.idle_wait(index, t_us, sight)
        acquire = not idle and self.should_acquire(index, t_us, sight)
        lost = not idle and sight.fix is None and \
            t_us - self.last_fix_us > self.config.search_after_s * 1e6
        # While tracks run, one heavy step per call (they take turns, issue 23): a call that
        # runs several holds a one-core board's next frame up by their sum.  With no track
        # the frames carry no fix to delay: then all at once, for the quickest start (taking
        # turns there too lost sitl_tests/test_one_landmark.py's box track for 1/3 of its
        # frames: re-acquired by the template search alone, it failed its checks).
        spread = bool(sight.seen.tracked)
        if acquire and lost and spread:
            self._lost_turn = not self._lost_turn
            acquire, lost = self._lost_turn, not self._lost_turn
        if acquire:
            self.acquired_frame = index
            starts += self.features.find(sight)
        predicted = self.prediction.find(sight, starts) \
            if sight.fix is not None or sight.guess is not None else []
        starts += predicted
        if sight.fix is None and lost and not predicted:  # (a guess's find: no search now)
            starts += self._find_while_lost(sight, spread)
        return starts

    def _find_while_lost(self, sight: Sighting, spread: bool) -> list[Start]:
        """Without a fix: the detector's hits, and the template search when they start
        nothing -- with ``spread``, on the next call (each costs 20-45 ms of CPU).  Neither
        counts what feature matching started on this call (as before the split: their
        seeds depend on it)."""
        if self.detector is not None and not self._search_next:
            found = self.detector.find(sight)
            if found or not spread:
                return found or self.search.find(sight)
            self._search_next = True
            return found
        self._search_next = False
        return self.search.find(sight)
