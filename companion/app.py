"""The one asyncio pipeline: source -> perception (trackers, pose) -> MAVLink, watched live.

    reader task ──LatestSlot (newest frame wins)──► worker task ──► sink (MAVLink bridge)
                                                      │  process() + observers' on_result()
                                                      │  in the worker thread
                                                      └─► background lane (its own thread):
                                                          housekeeping() + observers'
                                                          on_after_work() + preview
    status task (1 Hz and on every health change) ──────► monitor (Zenoh) + flight log

The critical path, capture -> fix on the wire, is :meth:`FrameProcessor.process` in the
worker thread, so the event loop stays free for heartbeats and telemetry.  What must not
delay the next frame (looking for new landmarks, drawing the preview) goes to a
:class:`~companion.pipeline.background.BackgroundLane` once the fix is out, and runs while
the worker already processes the next frame.  Every task is kept in ``self._tasks`` and
always finishes: :meth:`CompanionApp.run` returns only after all of them ended.

What else wants each result (the truth it is scored against, the SITL harness's record,
``companion replay --fast``'s pacing) subscribes as a :class:`ResultObserver`; nothing
wraps the processor.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import gc
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from companion.perception_types import TrackView
from companion.pipeline.background import BackgroundLane
from companion.pipeline.health import Blocker, HealthInputs, HealthPolicy, State, health_state
from companion.pipeline.keepup import KeepUpWatch
from companion.pipeline.latest import LatestSlot, SlotClosedError
from companion.pipeline.stats import RateMeter, Rolling
from companion.reporting import pose_json, tracks_json
from tracker.pose.types import PoseFix

log = logging.getLogger(__name__)


def now_us() -> int:
    """The companion's clock: monotonic, microseconds (frames are stamped with it)."""
    return time.monotonic_ns() // 1000


class Frame(Protocol):
    """What the pipeline needs of a frame (companion.sources.Frame satisfies it)."""

    @property
    def index(self) -> int: ...
    @property
    def t_us(self) -> int: ...
    @property
    def image(self) -> npt.NDArray[np.uint8]: ...
    @property
    def lossy(self) -> bool: ...


class FrameSource(Protocol):
    """``recv`` returns the next frame; raises EOFError at the end of a finite source."""

    async def recv(self) -> Frame: ...


@dataclass(frozen=True)
class FrameResult:
    """What perception made of one frame: typed values; their monitoring and flight-log JSON
    is built by :mod:`companion.reporting` (``pose_json``, ``track_json``)."""

    frame_index: int
    capture_t_us: int
    #: the live tracks at the frame's end, frozen copies
    tracks: tuple[TrackView, ...] = ()
    fix: PoseFix | None = None
    no_fix_reason: str | None = None
    events: tuple[dict[str, Any], ...] = ()
    bad_frame: bool = False
    #: Drawn on the preview, never logged: landmark id -> (N, 2) particle positions.
    particles: dict[str, npt.NDArray[np.float64]] = field(default_factory=dict)


class FrameProcessor(Protocol):
    """Synchronous per-frame work (tracking and pose); ``process`` runs in the worker thread.

    ``housekeeping`` runs after the frame's fix was sent, in the background lane's thread
    and so possibly *while* ``process`` works on a later frame: work that must not add
    latency (looking for new landmarks).  It sees frames in order, but not every frame
    when it is slower than the camera (the newest waiting frame wins).
    """

    def process(self, frame: Frame) -> FrameResult: ...
    def housekeeping(self, frame: Frame) -> None: ...


class ResultObserver(Protocol):
    """Subscribes to a flight's results (docs/architecture.md, "The observer contract").

    Observers are called in the order they were given to :class:`CompanionApp`; one that
    raises is a bug and stops the flight as a failing ``process`` does.  Subclass this to
    inherit the hooks you do not need (they do nothing).
    """

    def on_result(self, frame: Frame, result: FrameResult) -> None:
        """Every processed frame, in the worker thread right after ``process`` and before
        the fix goes on the wire (so keep it short): the next frame's ``process`` has not
        begun.  ``result`` is frozen: keep what you add beside it, never in it."""

    def on_after_work(self, frame: Frame) -> None:
        """In the background lane's thread, once the frame's ``housekeeping`` returned
        (before its preview is drawn); not called for a frame whose after-work the lane
        skipped (it was slower than the camera) or whose housekeeping raised."""
        return None

    def pose_fields(self, result: FrameResult) -> dict[str, Any]:
        """Fields this observer adds to the frame's ``pose`` report (flight log and Zenoh),
        asked on the event loop after ``on_result`` of the same frame (e.g. the truth)."""
        return {}


class FixSink(Protocol):
    """The autopilot side (the MAVLink bridge, or a test double)."""

    @property
    def link_up(self) -> bool: ...
    def set_health(self, state: State) -> None: ...
    async def send_fix(self, fix: Any) -> bool: ...
    async def statustext(self, text: str) -> None: ...
    def autopilot_position_ned(self) -> list[float] | None: ...


class Reporter(Protocol):
    """Where status, poses, tracks and events go (monitoring and the flight log)."""

    def report(self, topic: str, t_us: int, data: dict[str, Any]) -> None: ...
    def preview_due(self) -> bool: ...
    def preview(self, jpeg: bytes) -> None: ...


#: Draws a frame's preview: (frame, result) -> JPEG bytes.
PreviewFn = Callable[["Frame", "FrameResult"], bytes]


@dataclass
class Counters:
    """Counts shown in the status and the demo summary."""

    frames: int = 0
    bad_frames: int = 0
    fixes_sent: int = 0
    fixes_refused: int = 0
    no_fix: int = 0
    source_errors: int = 0
    worker_errors: int = 0
    housekeeping_skipped: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(vars(self))


@dataclass
class AppStats:
    """Latency per stage (ms) and rates, for the status and the summary."""

    capture_to_wire_ms: Rolling = field(default_factory=Rolling)
    process_ms: Rolling = field(default_factory=Rolling)
    queue_ms: Rolling = field(default_factory=Rolling)
    fps: RateMeter = field(default_factory=RateMeter)


class CompanionApp:
    """Owns the pipeline's tasks, its health state and its clean shutdown."""

    def __init__(self, source: FrameSource, processor: FrameProcessor, sink: FixSink,
                 reporter: Reporter, vehicle_id: str, status_period_s: float = 1.0,
                 policy: HealthPolicy | None = None,
                 clock_s: Callable[[], float] = time.monotonic,
                 preview: PreviewFn | None = None,
                 diagnose: Callable[[], Blocker | None] | None = None,
                 facts: dict[str, Any] | None = None,
                 observers: Sequence[ResultObserver] = (),
                 clock_us: Callable[[], int] = now_us) -> None:
        """``diagnose`` names why no fix can come (:class:`companion.nofix.NoFixWatch`);
        ``facts`` are fixed for the flight and shown in every status (e.g. the map);
        ``observers`` subscribe to the results (:class:`ResultObserver`), in this order;
        ``clock_us``: the clock the frames are stamped on, for their queueing, processing
        and capture-to-wire times (a replay on the recording's clock has its own)."""
        self.source = source
        self.processor = processor
        self.sink = sink
        self.reporter = reporter
        self.vehicle_id = vehicle_id
        self.status_period_s = status_period_s
        self.policy = policy or HealthPolicy()
        self.clock_s = clock_s
        self.preview = preview
        self.diagnose = diagnose
        self.facts = facts or {}
        self.observers = tuple(observers)
        self.clock_us = clock_us
        self.blocker: Blocker | None = None
        self.counters = Counters()
        self.stats = AppStats()
        self.keep_up = KeepUpWatch()
        self.state: State = "starting"
        self._slot: LatestSlot[Frame] = LatestSlot()
        self._executor = concurrent.futures.ThreadPoolExecutor(1, "companion-worker")
        self._background = BackgroundLane("companion-background", self._worker_failed)
        self._tasks: list[asyncio.Task[None]] = []
        self._stop = asyncio.Event()
        self._last_frame_s: float | None = None
        self._last_fix_s: float | None = None
        self._ever_tracked = False
        self._recent_bad: list[bool] = []
        #: How long :meth:`run` ran until it was asked to stop (the flight's own time).
        self.run_s = 0.0
        #: Why the source failed for good (None: it ended or was stopped).
        self.source_failure: Exception | None = None

    # -- public -----------------------------------------------------------------------

    def request_stop(self) -> None:
        """Ask every task to finish (signal handlers call this)."""
        self._stop.set()

    @property
    def dropped_frames(self) -> int:
        """Frames replaced in the slot before the worker took them."""
        return self._slot.dropped

    async def run(self, seconds: float | None = None) -> None:
        """Run until the source ends, ``seconds`` pass or :meth:`request_stop`.

        While it runs, what start-up made (maps, models, modules) is frozen out of the
        garbage collector's walks (``gc.freeze``, undone when it returns).  The GIL's
        switch interval stays CPython's 5 ms: 1 ms was tried for issue 23 and did no
        better on a loaded core (docs/benchmarks.md, "Latency tail").
        """
        # no gc.collect() first: the flight's clock runs already, and a full collection
        # took 80-330 ms here under load (start-up's little garbage stays, frozen)
        gc.freeze()
        self._tasks = [
            asyncio.create_task(self._reader(), name="reader"),
            asyncio.create_task(self._worker(), name="worker"),
            asyncio.create_task(self._status_loop(), name="status"),
        ]
        started_s = self.clock_s()
        try:
            if seconds is None:
                await self._stop.wait()
            else:
                await asyncio.wait_for(self._stop.wait(), timeout=seconds)
        except TimeoutError:
            pass
        finally:
            self.run_s = self.clock_s() - started_s
            await self._shutdown()
            gc.unfreeze()

    # -- tasks ------------------------------------------------------------------------

    async def _reader(self) -> None:
        try:
            while not self._stop.is_set():
                try:
                    frame = await self.source.recv()
                except EOFError:
                    log.info("frame source ended")
                    self._event("source-ended")
                    break
                self._last_frame_s = self.clock_s()
                self._slot.put(frame)
        except asyncio.CancelledError:
            pass
        except Exception as err:  # a source failure stops the flight cleanly, with a reason
            log.error("frame source failed: %s", err)
            self.source_failure = err
            self.counters.source_errors += 1
            self._event("source-failed", reason=str(err))
        finally:
            self._slot.close()
            self._stop.set()

    async def _worker(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            while True:
                frame = await self._slot.get()
                taken_us = self.clock_us()
                self.stats.queue_ms.add((taken_us - frame.t_us) / 1000.0)
                result = await loop.run_in_executor(self._executor, self._process, frame)
                self.stats.process_ms.add((self.clock_us() - taken_us) / 1000.0)
                await self._handle(result)
                self._after(frame, result)
        except (SlotClosedError, asyncio.CancelledError):
            pass
        except Exception as err:  # a bug in perception must stop the flight, loudly
            self._worker_failed(err)

    def _process(self, frame: Frame) -> FrameResult:
        """The worker thread's part: the processing, then the observers see the result."""
        result = self.processor.process(frame)
        for observer in self.observers:
            observer.on_result(frame, result)
        return result

    def _after(self, frame: Frame, result: FrameResult) -> None:
        """Hand the frame's after-work to the background lane (newest frame wins)."""
        preview = self.preview if self.preview is not None and self.reporter.preview_due() \
            else None

        def work() -> bytes | None:
            self.processor.housekeeping(frame)
            for observer in self.observers:
                observer.on_after_work(frame)
            return None if preview is None else preview(frame, result)

        def done(jpeg: bytes | None) -> None:
            if jpeg is not None:
                self.reporter.preview(jpeg)

        self._background.submit(work, done)
        self.counters.housekeeping_skipped = self._background.dropped

    def _worker_failed(self, err: BaseException) -> None:
        log.error("frame processing failed: %s", err, exc_info=err)
        self.counters.worker_errors += 1
        self._event("worker-failed", reason=f"{type(err).__name__}: {err}")
        self._stop.set()
        self._slot.close()

    async def _handle(self, result: FrameResult) -> None:
        """The fix goes on the wire first; counting and reporting come after it."""
        now_s = self.clock_s()
        sent = result.fix is not None and await self.sink.send_fix(result.fix)
        if sent:
            self.stats.capture_to_wire_ms.add((self.clock_us() - result.capture_t_us) / 1000.0)
        self.counters.frames += 1
        self.stats.fps.tick(now_s)
        self._recent_bad = [*self._recent_bad[-29:], result.bad_frame]
        if result.bad_frame:
            self.counters.bad_frames += 1
        for event in result.events:
            self.reporter.report("events", result.capture_t_us, event)
        self.reporter.report("tracks", result.capture_t_us,
                             {"frame": result.frame_index, "tracks": tracks_json(result.tracks),
                              "no_fix_reason": result.no_fix_reason})
        if result.tracks:
            self._ever_tracked = True
        if result.fix is None:
            self.counters.no_fix += 1
        elif sent:
            self.counters.fixes_sent += 1
            self._last_fix_s = now_s
            own = self.sink.autopilot_position_ned()  # to plot the fix against it
            extra = {} if own is None else {"autopilot_position_ned_m": own}
            added = {k: v for o in self.observers for k, v in o.pose_fields(result).items()}
            self.reporter.report("pose", result.capture_t_us,
                                 {**pose_json(result.fix), **added, **extra})
        else:  # refused by the bridge: visible with its reason (flight log, Zenoh)
            self.counters.fixes_refused += 1
            self.reporter.report("events", result.capture_t_us, {
                "event": "fix-refused", "frame": result.frame_index,
                "reason": getattr(self.sink, "last_result", None) or "refused"})
        self._update_health()

    async def _status_loop(self) -> None:
        try:
            while not self._stop.is_set():
                self._update_health()
                await self._watch_keep_up()
                self.reporter.report("status", self.clock_us(), self.status())
                try:
                    await asyncio.wait_for(self._stop.wait(), self.status_period_s)
                except TimeoutError:
                    pass
        except asyncio.CancelledError:
            pass

    # -- state ------------------------------------------------------------------------

    def _update_health(self) -> None:
        bad_ratio = sum(self._recent_bad) / len(self._recent_bad) if self._recent_bad else 0.0
        blocker = self.diagnose() if self.diagnose is not None else None
        state = health_state(
            HealthInputs(self.clock_s(), self.counters.frames, self._last_frame_s,
                         self._last_fix_s, self._ever_tracked, self.sink.link_up, bad_ratio,
                         blocker),
            self.policy,
        )
        self._note_blocker(blocker if state == "blocked" else None)
        self.sink.set_health(state)  # every time: the heartbeat shows the app is alive
        if state != self.state:
            old, self.state = self.state, state
            log.info("health %s -> %s", old, state)
            self._event("health", old=old, new=state)
            self.reporter.report("status", self.clock_us(), self.status())

    async def _watch_keep_up(self) -> None:
        """Say once when the processing falls behind the camera (frames dropped), and
        when it keeps up again (:mod:`companion.pipeline.keepup`)."""
        change = self.keep_up.update(self.clock_s(), self.counters.frames, self.dropped_frames)
        c = self.keep_up.last
        if change is None or c is None:
            return
        fields = {"frames": c.frames, "dropped": c.dropped, "window_s": round(c.window_s, 1),
                  "share": round(c.share, 3)}
        if not change:
            log.info("keeping up with the camera again: %d of %d frames dropped in the last "
                     "%.0f s", c.dropped, c.frames + c.dropped, c.window_s)
            self._event("keeping-up", **fields)
            return
        log.warning("%s, processing p99 %s ms: lower perception.max_tracks or the "
                    "resolution, or free a core (docs/deploy.md, 'Latency on a slower "
                    "board')", self.keep_up.warning(), self.stats.process_ms.summary()["p99"])
        self._event("falling-behind", **fields)
        try:
            await self.sink.statustext(f"{100 * c.share:.0f}% of camera frames dropped (CPU)")
        except Exception as err:  # the link may be down: the log and the status say it
            log.warning("STATUSTEXT not sent: %s", err)

    def report_event(self, name: str, fields: dict[str, Any]) -> None:
        """Publish an event (monitoring and the flight log) stamped now."""
        self._event(name, **fields)

    def _note_blocker(self, blocker: Blocker | None) -> None:
        """Log and publish a change of the reason no fix can come (its detail, e.g. how
        long the link has been silent, is refreshed in the status without a new event)."""
        previous, self.blocker = self.blocker, blocker
        if (previous and previous.cause) == (blocker and blocker.cause):
            return
        if blocker is not None:
            log.warning("no fix can come: %s: %s", blocker.cause, blocker.detail)
            self._event("no-fix", **blocker.as_dict())
        elif previous is not None:
            log.info("no longer blocked (%s)", previous.cause)
            self._event("no-fix-cleared", cause=previous.cause)

    def _event(self, name: str, **fields: Any) -> None:
        self.reporter.report("events", self.clock_us(), {"event": name, **fields})

    def status(self) -> dict[str, Any]:
        """The status payload (docs/monitoring.md)."""
        source_status = getattr(self.source, "status", None)
        as_dict = getattr(source_status, "as_dict", None)
        source: dict[str, Any] = as_dict() if callable(as_dict) else {}
        streams = getattr(self.sink, "autopilot_streams", None)
        warnings = getattr(self.sink, "warnings", None)
        return {
            "vehicle": self.vehicle_id,
            "state": self.state,
            "no_fix_cause": None if self.blocker is None else self.blocker.as_dict(),
            "fps": round(self.stats.fps.rate(self.clock_s()), 2),
            "latency_ms": self.stats.capture_to_wire_ms.summary(),
            "link": "up" if self.sink.link_up else "down",
            "counters": self.counters.as_dict(),
            "dropped_frames": self.dropped_frames + int(source.get("skipped", 0)),
            "source": source,
            "autopilot_streams": streams() if callable(streams) else {},
            "warnings": [*(warnings() if callable(warnings) else []),
                         *filter(None, [self.keep_up.warning()])],
            **self.facts,
        }

    async def _shutdown(self) -> None:
        self._stop.set()
        self._slot.close()
        for task in self._tasks:
            if task.get_name() == "reader":
                task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await self._background.close()
        self._executor.shutdown(wait=True)
        self._event("stopped", frames=self.counters.frames)
        try:
            await self.sink.statustext(f"stopped after {self.counters.frames} frames")
        except Exception as err:  # the link may already be gone
            log.warning("final STATUSTEXT not sent: %s", err)
        self.reporter.report("status", self.clock_us(), self.status())
