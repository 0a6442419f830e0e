"""The frame's two threads on a core each, while the machine leaves them free (issue 23).

A frame's track updates run on two threads: the frame worker and the track set's second
thread (:mod:`companion.tracks`).  Left to the scheduler, the second thread is woken onto
the worker's core at every hand-over and waits there, runnable, while the other core idles:
on the project's 2-core machine a quarter of the heavy frames' track-update time went on
run-queue waits, and the two threads ran one at a time (docs/benchmarks.md, "Latency tail
(issue 23)", 2026-12-05 afternoon).  Kept to a core each they run side by side.

A thread kept to a core cannot leave it, though: beside another busy process it gets half
of that core (a busy loop beside the demo: p99 22-25 -> 24-32 ms, kept for the whole
flight).  So :class:`CoreKeeper` looks once a window (``WINDOW_FRAMES`` frames): it keeps
the threads only while other processes used at most ``MAX_OTHERS_CORES`` cores over the
window on the cores the process may use (their busy time, ``/proc/stat``, less this
process's: on a board that gives the companion cores of its own by ``CPUAffinity=``, the
load on the others does not count), and lets them go when they did, or when the kept
threads waited more than ``MAX_WAIT_SHARE`` of their time on a run queue
(``/proc/self/task/TID/schedstat``); after that it waits ``PAUSE_WINDOWS`` windows before
keeping them again.  It keeps them only where the process may run on two cores or more
(the last two of its set: the system's own work tends to the first ones), on Linux.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Callable

log = logging.getLogger(__name__)

#: frames between two looks (~1 s at 30 fps)
WINDOW_FRAMES = 30
#: the cores other processes may keep busy and still leave the frame threads theirs
MAX_OTHERS_CORES = 0.5
#: kept threads that waited more than this share of their time on a core go free ...
MAX_WAIT_SHARE = 0.15
#: ... for this many windows
PAUSE_WINDOWS = 10

#: (ns on a core, ns runnable on a run queue) of a thread of this process, None if unknown
Reader = Callable[[int], tuple[int, int] | None]
#: sets the allowed cores of a thread of this process (by its native id)
Setter = Callable[[int, set[int]], None]
#: of the given cores: (their busy ticks, all their ticks, how many cores were read, this
#: process's CPU ticks), None if unknown
Load = Callable[[set[int] | None], tuple[int, int, int, int] | None]


def schedstat(tid: int) -> tuple[int, int] | None:
    """Thread ``tid``'s time on a core and on a run queue so far (ns), from the kernel's
    scheduler statistics; None where it keeps none or the thread has ended."""
    try:
        with open(f"/proc/self/task/{tid}/schedstat") as fh:
            run, wait = fh.read().split()[:2]
        return int(run), int(wait)
    except (OSError, ValueError):
        return None


def machine_load(cores: set[int] | None = None, stat: str = "/proc/stat",
                 own: str = "/proc/self/stat") -> tuple[int, int, int, int] | None:
    """The busy and total clock ticks of ``cores`` (``/proc/stat``'s line of each; every
    core when None; idle and waiting for I/O are not busy), how many cores that was (a core
    offline has no line) and this process's CPU ticks (``/proc/self/stat``); None when a
    reading is missing."""
    try:
        with open(stat) as fh:
            lines = [line.split() for line in fh if line.startswith("cpu")]
        picked = [line for line in lines[1:] if int(line[0][3:]) in cores] \
            if cores is not None else lines[1:]
        busy = total = 0
        for line in picked:
            ticks = [int(v) for v in line[1:]]
            busy += sum(ticks) - ticks[3] - ticks[4]
            total += sum(ticks)
        with open(own) as fh:
            mine = fh.read().rsplit(")", 1)[1].split()
        return (busy, total, len(picked), int(mine[11]) + int(mine[12])) if picked else None
    except (OSError, ValueError, IndexError):
        return None


def process_cores() -> set[int]:
    """The cores this process may run on (its main thread's set: a thread kept to one core
    reads only that one as its own)."""
    if not hasattr(os, "sched_getaffinity"):
        return set()
    return set(os.sched_getaffinity(os.getpid()))


class CoreKeeper:
    """Keeps the frame worker and one other thread on a core each (the module's notes).

    Call :meth:`frame` on the worker thread at each frame, before its track updates, with
    the other thread's native id (0 until it has one); :meth:`release` at the end.  Called
    on the process's main thread (a benchmark or a test driving the perception itself) it
    keeps nothing: that thread's set is the process's, and the processes it starts inherit
    it.  Without ``cores`` the process's cores are read (``process``) and read again at
    each look: moved by ``taskset`` or a cgroup, the threads follow (while the process has
    two cores or more).  The readers and the setter are injectable for tests."""

    def __init__(self, cores: set[int] | None = None, *, read: Reader = schedstat,
                 set_cores: Setter | None = None, load: Load = machine_load,
                 any_thread: bool = False,
                 process: Callable[[], set[int]] = process_cores) -> None:
        self._follow = process if cores is None else None
        self._use(process() if cores is None else cores)
        self._read, self._load = read, load
        self._set = set_cores or _set_affinity
        self._any_thread = any_thread  # tests: the main thread may be kept too
        self.kept = False
        self.worker = self.other = 0
        self.released = 0  # times let go
        self._frames = 0
        self._pause = 0
        self._since: tuple[int, ...] | None = None  # see _sample
        self._looked = False  # the first frame starts the first window

    def frame(self, other_tid: int) -> None:
        """Count a frame; once a window, keep or let go (see the module's notes)."""
        on_main = threading.current_thread() is threading.main_thread()
        if self.pair is None or other_tid == 0 or (on_main and not self._any_thread):
            return  # (the main thread's set is the process's, and its children inherit it)
        self.worker, self.other = threading.get_native_id(), other_tid
        self._frames += 1
        if self._looked and self._frames < WINDOW_FRAMES:
            return  # (a missing reading is tried again a window later, not every frame)
        if self._follow is not None and (moved := self._follow()) and moved != self.all:
            self._use(moved)  # a new window: the load read was of other cores
            self._since, self._looked = None, False
            self._release(f"the process's cores are now {sorted(moved)}")
            return
        before, now = self._since, self._sample()
        self._since, self._frames, self._looked = now, 0, True
        if before is None or now is None:
            return
        run, wait = now[0] - before[0], now[1] - before[1]
        ticks = max(now[3] - before[3], 1)  # over now[4] cores
        others = ((now[2] - before[2]) - (now[5] - before[5])) / ticks * now[4]
        self._pause = max(0, self._pause - 1)
        if self.kept and run > 0 and wait > MAX_WAIT_SHARE * run:
            self._pause = PAUSE_WINDOWS
            self._release(f"they waited {wait / run:.0%} of their time for their cores")
        elif self.kept and others > MAX_OTHERS_CORES:
            self._release(f"other processes kept {others:.1f} cores busy")
        elif not self.kept and others <= MAX_OTHERS_CORES and not self._pause:
            self._keep()

    def _use(self, cores: set[int]) -> None:
        allowed = sorted(cores)
        self.all = set(allowed)
        self.pair = (allowed[-2], allowed[-1]) if len(allowed) >= 2 else None

    def release(self) -> None:
        """Both threads back on every core of the process (at the end of a flight)."""
        if self.kept:
            self._release("")

    def _keep(self) -> None:
        assert self.pair is not None
        try:
            self._set(self.worker, {self.pair[0]})
            self._set(self.other, {self.pair[1]})
        except OSError as err:  # a core taken away meanwhile: leave them free for good
            self.pair = None
            self._release(f"not kept: {err}")
            return
        self.kept = True
        log.debug("frame threads kept on cores %d and %d", *self.pair)

    def _release(self, why: str) -> None:
        for tid in (self.worker, self.other):
            try:
                self._set(tid, self.all)
            except OSError:
                pass  # the thread has ended
        self.kept = False
        if why:
            self.released += 1
            log.debug("frame threads free to move: %s", why)

    def _sample(self) -> tuple[int, ...] | None:
        """Both threads' run and wait (ns), then :data:`Load`'s reading of the process's
        cores; None when a reading is missing."""
        a, b, load = self._read(self.worker), self._read(self.other), self._load(self.all)
        if a is None or b is None or load is None:
            return None
        return a[0] + b[0], a[1] + b[1], *load


def _set_affinity(tid: int, cores: set[int]) -> None:
    os.sched_setaffinity(tid, cores)
