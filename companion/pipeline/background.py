"""A lane for work that must never delay the next frame: one thread, newest job wins.

The worker hands a frame's after-work (looking for new landmarks, drawing the preview) to
this lane once the frame's fix is on the wire, and goes straight back to the next frame.
While a job runs, later jobs wait in a one-place slot: a newer one replaces an older one
(counted in ``dropped``), like frames in :class:`~companion.pipeline.latest.LatestSlot` --
acquisition on a stale frame is worth less than acquisition on the newest.

Results and errors come back on the event loop (``on_done`` / ``on_error`` are called
there), so whoever consumes them needs no locks.  Only for use on one event loop.

The lane's thread runs at a lower scheduling priority (``nice``, default +3 over the
process): on a core shared with the worker, the kernel gives the worker the larger share
(about 2:1) while both want it.  Not more: at +10 a busy process on the same core starved
acquisition (half the fixes).  Its native work (feature matching, template search, the
detector) releases the GIL.  Issue 23's measurements: docs/benchmarks.md.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

log = logging.getLogger(__name__)


def lower_thread_priority(nice: int) -> None:
    """Lower the calling thread's scheduling priority by ``nice`` (Linux schedules threads
    one by one: ``setpriority`` on the thread's id); a no-op where that is not possible."""
    if nice <= 0 or not hasattr(os, "setpriority"):
        return
    tid = threading.get_native_id()
    with contextlib.suppress(OSError):
        current = os.getpriority(os.PRIO_PROCESS, tid)
        os.setpriority(os.PRIO_PROCESS, tid, min(19, current + nice))


@dataclass(frozen=True)
class _Job:
    work: Callable[[], Any]
    on_done: Callable[[Any], None]


class BackgroundLane:
    """Runs jobs one at a time on its own thread; at most one more waits (the newest)."""

    def __init__(self, name: str, on_error: Callable[[BaseException], None],
                 nice: int = 3) -> None:
        self._executor = concurrent.futures.ThreadPoolExecutor(
            1, name, initializer=lower_thread_priority, initargs=(nice,))
        self._on_error = on_error
        self._running: asyncio.Future[Any] | None = None
        self._waiting: _Job | None = None
        self._closed = False
        self.dropped = 0
        self.done = 0

    @property
    def busy(self) -> bool:
        """A job is running."""
        return self._running is not None

    def submit(self, work: Callable[[], Any], on_done: Callable[[Any], None]) -> None:
        """Run ``work`` now if the lane is idle, else keep it as the next job (replacing
        a job that was waiting: that one is dropped)."""
        if self._closed:
            return
        job = _Job(work, on_done)
        if self._running is None:
            self._start(job)
            return
        if self._waiting is not None:
            self.dropped += 1
        self._waiting = job

    def _start(self, job: _Job) -> None:
        loop = asyncio.get_running_loop()
        future = loop.run_in_executor(self._executor, job.work)
        self._running = future
        future.add_done_callback(lambda f: self._finished(f, job))

    def _finished(self, future: asyncio.Future[Any], job: _Job) -> None:
        self._running = None
        if future.cancelled():
            return
        err = future.exception()
        if err is not None:
            self._waiting = None
            self._on_error(err)
            return
        self.done += 1
        try:
            job.on_done(future.result())
        except Exception as exc:  # a consumer's bug must surface like the job's own
            self._on_error(exc)
            return
        waiting, self._waiting = self._waiting, None
        if waiting is not None and not self._closed:
            self._start(waiting)

    async def close(self) -> None:
        """Drop the waiting job, let the running one finish, stop the thread."""
        self._closed = True
        self._waiting = None
        running = self._running
        if running is not None:
            await asyncio.gather(running, return_exceptions=True)
        self._executor.shutdown(wait=True)
