"""The perception's track set: the live tracks, their update each frame, their checks.

Threads -- who may touch what:

* The **worker thread** (``Perception.process``) owns the tracks: it alone changes the set
  (adopts, drops) and the :class:`~companion.perception_types.Track` objects.  During
  :meth:`TrackSet.update`, it and the set's own second thread ("companion-tracks") take
  the tracks from one queue, the dearest first; each update touches only its own track
  (and the corner recovery's matcher, behind :class:`companion.corners.Corners`' lock),
  and ``update`` waits for both threads before it returns.
* The **background lane** (``Perception.housekeeping``) never reads the tracks.  It takes
  :meth:`TrackSet.snapshot` -- a frozen :class:`~companion.perception_types.Occupancy`
  (which landmarks are tracked or waiting), made under the set's lock, under which the
  worker also makes every change to the set -- and hands what it started over with
  :meth:`TrackSet.hand_over`, under the same lock; the next :meth:`TrackSet.adopt` on the
  worker thread takes them.
* Everything else shared (references, map, configuration) is read-only.

:attr:`TrackSet.live` is the worker thread's own view, for code running on that thread or
between frames (tests, benchmarks, the replay's scorer); results carry frozen copies
(:meth:`TrackSet.views`).
"""

from __future__ import annotations

import concurrent.futures
import itertools
import threading
import time
from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from companion.cores import CoreKeeper
from companion.corner_noise import CornerNoise
from companion.corners import Corners
from companion.perception_types import Occupancy, PerceptionConfig, Start, Track, TrackView
from tracker.boxes import box_corners, inside
from tracker.geometry import FloatArray
from tracker.pose.types import NoFix, Observation, PoseFix
from tracker.types import TrackResult

Events = list[dict[str, Any]]


class TrackSet:
    """The live tracks of one perception (see the module's notes on threads)."""

    def __init__(self, config: PerceptionConfig, corners: Corners) -> None:
        self.config = config
        self.corners = corners
        self._tracks: dict[str, Track] = {}
        self._lock = threading.Lock()  # the set's changes, the snapshot and the hand-over
        self._pending: list[Start] = []
        self._pool_tid = 0  # the second thread's native id, once it runs
        self._pool = concurrent.futures.ThreadPoolExecutor(
            1, "companion-tracks", initializer=self._note_thread) \
            if config.parallel_tracks else None
        self._keeper = CoreKeeper() \
            if config.parallel_tracks and config.keep_frame_cores else None
        self._checked: dict[str, float] = {}  # this frame's appearance checks (correlation)
        self._early: frozenset[str] = frozenset()  # turns taken early (_spread_turns)
        self._frames = 0

    def _note_thread(self) -> None:
        self._pool_tid = threading.get_native_id()

    @property
    def live(self) -> dict[str, Track]:
        """The tracks by landmark id (the worker thread's: see the module's notes)."""
        return self._tracks

    # -- the hand-over (background lane <-> worker) ------------------------------------

    def snapshot(self) -> Occupancy:
        """Which landmarks are tracked or waiting to be adopted, and where, as of now (any
        thread)."""
        with self._lock:
            return Occupancy(frozenset(self._tracks),
                             tuple(s.track.landmark_id for s in self._pending),
                             tuple(t.box for t in self._tracks.values())
                             + tuple(s.track.box for s in self._pending))

    def hand_over(self, starts: Sequence[Start]) -> None:
        """Tracks started off the worker thread, for the next :meth:`adopt`."""
        with self._lock:
            self._pending += starts

    def adopt(self) -> Events:
        """Take over the tracks handed over (worker thread), each with its event; a
        landmark already tracked, or a full set, drops the newcomer."""
        with self._lock:
            pending, self._pending = self._pending, []
            events: Events = []
            for start in pending:
                lid = start.track.landmark_id
                if lid not in self._tracks and len(self._tracks) < self.config.max_tracks:
                    self._tracks[lid] = start.track
                    events.append(start.event)
        return events

    def _drop(self, lid: str) -> None:
        with self._lock:
            del self._tracks[lid]

    # -- the frame's update (worker thread) --------------------------------------------

    def update(self, image: npt.NDArray[np.uint8], check_all: bool = False,
               motion: FloatArray | None = None) -> Events:
        """Update every track on ``image``; a track its tracker lost is dropped (an event).

        Each track's appearance check is due every ``verify_every_frames``, the tracks'
        checks on different frames (issue 23: not every track's on one frame), and all at
        once with ``check_all`` (a light step); a track is checked right after its update,
        on its thread.  ``motion``: the image's move since the last frame for the camera's
        turn (:mod:`companion.ego_motion`), where the corners' alignment starts."""
        events: Events = []
        tracks = list(self._tracks.values())
        every = self.config.verify_every_frames
        checks = [check_all or (self._frames + i) % every == 0 for i in range(len(tracks))]
        self._spread_turns(tracks)
        if self._keeper is not None:  # every frame: its looks a second apart
            self._keeper.frame(self._pool_tid)
        alive_now = self._update_all(tracks, image, checks, motion)
        for track, alive in zip(tracks, alive_now, strict=True):
            if not alive:
                self._drop(track.landmark_id)
                events.append({"event": "lost", "landmark": track.landmark_id})
        if any(checks):
            events += self.verify()
        self._frames += 1
        return events

    def _update_all(self, tracks: list[Track], image: npt.NDArray[np.uint8],
                    checks: Sequence[bool], motion: FloatArray | None = None) -> list[bool]:
        """Update every track (and check those whose ``checks`` entry is true); with two
        or more, this thread and the second one take the tracks from one queue, dearest
        first (the tracker's turn due, then the last update's CPU), each the next as it
        is free: a frame waits for the larger share, not for a fixed half (issue 23:
        three tracks split two and one kept 12-26 ms on the second thread while this
        one waited).  Each update touches only its own track."""
        if self._pool is None or len(tracks) < 2:
            return [self._update_one(t, image, c, motion)
                    for t, c in zip(tracks, checks, strict=True)]
        order = iter(sorted(range(len(tracks)), key=lambda i: (
            not self._turn_due(tracks[i]), -tracks[i].cost_s)))
        taking = threading.Lock()
        alive = [True] * len(tracks)

        def drain() -> None:
            while True:
                with taking:
                    i = next(order, None)
                if i is None:
                    return
                alive[i] = self._update_one(tracks[i], image, checks[i], motion)

        there = self._pool.submit(drain)
        try:
            drain()
        finally:
            there.result()  # never leave a track updating into the next frame
        return alive

    def _update_one(self, track: Track, image: npt.NDArray[np.uint8], check: bool,
                    motion: FloatArray | None = None) -> bool:
        """The tracker's update and the corners' alignment (and the appearance check when
        ``check``); False when the track is lost."""
        started = time.thread_time()
        try:
            return self._update_track(track, image, check, motion)
        finally:
            track.cost_s = time.thread_time() - started

    def _update_track(self, track: Track, image: npt.NDArray[np.uint8], check: bool,
                      motion: FloatArray | None) -> bool:
        track.frames += 1
        if not self._coasted(track, image, motion):
            result: TrackResult = track.tracker.update(image)
            if result.box is None or result.confidence < self.config.min_track_confidence:
                track.tried = None
                return False
            last_box, track.box = track.box, result.box
            track.confidence, track.features = result.confidence, result.features
            track.coasted = 0
            self.corners.follow(track, image, last_box, motion)
            if self.corners.left_view(track):
                track.tried = None
                return False  # the plate has left the image (corners.LEFT_VIEW_SHARE)
        track.tried = None
        if check:
            # one key per track: no two threads share one
            self._checked[track.landmark_id] = self.corners.check(track, image)
        return True

    def _coasted(self, track: Track, image: npt.NDArray[np.uint8],
                 motion: FloatArray | None) -> bool:
        """Between the tracker's frames (``track_every_frames``): the corners aligned
        without it, the tracker's box moved as the outline moved; False when it is the
        tracker's turn or the alignment alone did not hold."""
        before = track.corners
        if self._turn_due(track) or not self.corners.coast(track, image, motion):
            return False
        after = track.corners
        assert before is not None and after is not None  # _turn_due: corners before
        shift = after.mean(axis=0) - before.mean(axis=0)
        ratio = float(np.sqrt(cv2.contourArea(after.astype(np.float32))
                              / cv2.contourArea(before.astype(np.float32))))
        track.box = track.tracker.coast((float(shift[0]), float(shift[1])), ratio)
        track.coasted += 1
        return True

    def _turn_due(self, track: Track) -> bool:
        """The particle tracker updates ``track`` on this frame (no coasting)."""
        return track.coasted + 1 >= self.config.track_every_frames or track.corners is None \
            or track.tracker.state.lost_frames > 0 or track.landmark_id in self._early

    def _spread_turns(self, tracks: Sequence[Track]) -> None:
        """Set ``_early``: the track that takes its tracker's turn early on this frame, if
        any: on a frame where no turn is due, one of two tracks whose turns would fall on
        the same later frame (issue 23: a turn costs about twice a coasting frame, and
        three tracks with two or three turns on one frame made the latency's tail).  Turns
        only come earlier, never later than ``track_every_frames`` apart."""
        every = self.config.track_every_frames
        self._early = frozenset()  # the last frame's, out of the waits below
        waits = sorted((0 if self._turn_due(t) else every - 1 - t.coasted, t.landmark_id)
                       for t in tracks)
        if waits and waits[0][0] > 0:
            self._early = next((frozenset({lid}) for (wait, _), (later, lid)
                                in itertools.pairwise(waits) if wait == later), frozenset())

    def verify(self, image: npt.NDArray[np.uint8] | None = None) -> Events:
        """Check every track on ``image`` (None: :meth:`update` has, with the tracks'
        updates); a track that failed is left out of fixes, dropped after repeated
        failures."""
        if image is not None:
            for track in list(self._tracks.values()):
                self._checked[track.landmark_id] = self.corners.check(track, image)
        events: Events = []
        checked, self._checked = self._checked, {}
        for track in list(self._tracks.values()):
            if track.verify_failures >= self.config.max_verify_failures:
                self._drop(track.landmark_id)
                ncc = checked.get(track.landmark_id, 0.0)
                events.append({"event": "lost", "landmark": track.landmark_id,
                               "why": f"appearance no longer there (correlation {ncc:.2f})"})
        return events

    def drop_rejected(self, observations: Sequence[Observation], fix: PoseFix | NoFix
                      ) -> Events:
        """Count, per track, the solved frames in a row that left its corners out -- of the
        fix, or named as the one of three landmarks that did not fit (no fix then: too few
        to drop it, ``NoFix.outlier``) -- and drop a track at ``max_pose_rejections``
        (housekeeping then acquires it afresh). A frame without a fix that names no
        landmark changes no count."""
        limit = self.config.max_pose_rejections
        events: Events = []
        blamed = fix.outlier if isinstance(fix, NoFix) else None
        if isinstance(fix, NoFix) and blamed is None:
            return events
        for o in observations:
            track = None if o.landmark_id is None else self._tracks.get(o.landmark_id)
            if track is None or o.corners_px is None:
                continue
            if blamed is not None and o.landmark_id != blamed:
                continue  # a frame without a fix: only the named one is counted
            used = isinstance(fix, PoseFix) and o.landmark_id in fix.landmark_ids
            track.pose_rejections = 0 if used else track.pose_rejections + 1
            if limit and track.pose_rejections >= limit:
                self._drop(track.landmark_id)
                events.append({"event": "lost", "landmark": track.landmark_id,
                               "why": f"its corners left out of {limit} fixes in a row"})
        return events

    # -- what a frame's result carries ---------------------------------------------------

    def views(self) -> tuple[TrackView, ...]:
        """Frozen copies of the live tracks, for the frame's result."""
        return tuple(TrackView.of(t) for t in self._tracks.values())

    def particles(self) -> dict[str, npt.NDArray[np.float64]]:
        """Landmark id -> its tracker's particle centres (the preview draws them)."""
        return {t.landmark_id: t.tracker.particle_centres for t in self._tracks.values()}

    def close(self) -> None:
        """Stop the track-update thread."""
        if self._keeper is not None:
            self._keeper.release()
        if self._pool is not None:
            self._pool.shutdown(wait=True)


def observations(tracks: Mapping[str, Track], noise: CornerNoise, config: PerceptionConfig,
                 frame_index: int) -> list[Observation]:
    """One observation per live track (corners when the alignment holds).

    A plate cut by the image's edge (less than ``min_corner_in_view`` of it in view)
    gives the corners its outline puts inside the image by ``EDGE_MARGIN_PX``
    (:mod:`companion.corner_noise`) as measured (``Observation.corners_measured``); the
    ones outside are extrapolations, not observations.  Their sigma grows as the part in
    view shrinks (:meth:`CornerNoise.cut`).  A plate whose outline crosses the image's edge
    at all states its corners no better than ``young_cut_sigma_rel`` of the outline's size
    in its track's first ``young_cut_frames``.  When some tracks have corners, box-only tracks
    are left out: a box centre is not the landmark's centre under perspective, and mixing
    it in costs more than it adds.  Without corners, a box that reaches out of the image is
    left out too: its centre is off its plate's by up to half the part out of view; and so
    is a ``disputed`` one (its outline found elsewhere: a tracker box 20-30 px off a plate
    that had just come whole into view gave a fix 2.8 m off, survey frame 84).
    """
    out = []
    size = (noise.camera.width, noise.camera.height)

    def crossing(t: Track) -> bool:
        return t.corners is not None and not inside(t.corners, *size, margin=0.0)
    live = [t for t in tracks.values() if t.verify_failures == 0]
    usable = {t.landmark_id: noise.cut(t) for t in live
              if t.corners is not None and t.saturated <= config.max_corner_saturated}
    # a plate crossing the image's edge has its fit sigma from its whole outline (what is
    # out of view too): not held against the size model, but stated (the larger of the
    # two, CornerNoise.sigma)
    usable = {lid: cut for lid, cut in usable.items() if cut is not None
              and (crossing(tracks[lid]) or noise.fits(tracks[lid]))}
    if usable:
        live = [t for t in live if t.landmark_id in usable]
    else:  # boxes only: a box reaching out of the image is not centred on its plate, nor
        # one that has disagreed with its plate's outline since the alignment last held,
        # nor one holding the part of its plate that was in view when it was seated
        live = [t for t in live if inside(box_corners(t.box), *size, margin=1.0)
                and not t.disputed and not t.partial_box]
    for t in live:
        x, y, w, h = t.box
        cut = usable.get(t.landmark_id)
        corners = None if t.corners is None or cut is None else tuple(
            (float(u), float(v)) for u, v in t.corners)
        centre = ((x + w / 2, y + h / 2) if corners is None
                  else tuple(float(c) for c in np.mean(corners, axis=0)))
        stretch = 1.0 if corners is None else noise.stretch(corners)  # once a plate
        scale = None if corners is None else config.corner_scale_sigma_px * stretch
        sigma = noise.stated(t, corners, stretch)
        measured, grow = (None, 1.0) if cut is None else cut
        outside = None
        if sigma is not None:
            sigma *= grow
            extent = float(np.sqrt(abs(cv2.contourArea(np.asarray(corners, np.float32)))))
            if noise.unsettled(t):
                sigma = max(sigma, config.young_cut_sigma_rel * extent)
            if measured is not None and t.outline_held and config.cut_extrapolated_sigma_rel > 0:
                outside = max(sigma, config.cut_extrapolated_sigma_rel * extent)
        out.append(Observation(centre_px=(float(centre[0]), float(centre[1])),
                               box_wh_px=(w, h), confidence=t.confidence,
                               landmark_id=t.landmark_id, corners_px=corners,
                               frame_index=frame_index,
                               corner_sigma_px=sigma,
                               corner_scale_sigma_px=scale, corners_measured=measured,
                               extrapolated_sigma_px=outside,
                               corner_mode_sigma_rel=None if corners is None
                               else noise.modes(t)))
    return out
