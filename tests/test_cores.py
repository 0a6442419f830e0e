"""companion.cores: the frame's two threads kept on a core each while the machine leaves
them free, and let go when it does not."""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path

import pytest

from companion import cores
from companion.cores import MAX_OTHERS_CORES, PAUSE_WINDOWS, WINDOW_FRAMES, CoreKeeper


class Machine:
    """Scripted scheduler statistics: per window, the frame threads' run and wait (ms) and
    the cores other processes kept busy on the process's cores."""

    def __init__(self) -> None:
        self.run_ns = self.wait_ns = 0
        self.seconds = self.busy = self.own = 0
        self.sets: list[tuple[int, set[int]]] = []
        self.asked: list[set[int] | None] = []

    def window(self, others: float, run_ms: float = 500.0, wait_ms: float = 10.0,
               own_cores: float = 0.4) -> None:
        """One second passes."""
        self.run_ns += int(run_ms * 1e6)
        self.wait_ns += int(wait_ms * 1e6)
        self.seconds += 1
        self.own += round(own_cores * 100)
        self.busy += round((own_cores + others) * 100)

    def read(self, tid: int) -> tuple[int, int]:
        return self.run_ns // 2, self.wait_ns // 2  # each thread half

    def load(self, cores: set[int] | None) -> tuple[int, int, int, int]:
        self.asked.append(cores)
        n = len(cores or {0, 1})
        return self.busy, 100 * n * self.seconds, n, self.own

    def set_cores(self, tid: int, allowed: set[int]) -> None:
        self.sets.append((tid, set(allowed)))


def keeper(m: Machine, allowed: set[int] | None = None) -> CoreKeeper:
    return CoreKeeper({0, 1} if allowed is None else allowed, read=m.read,
                      set_cores=m.set_cores, load=m.load, any_thread=True)


def frames(k: CoreKeeper, m: Machine, others: float, **kw: float) -> None:
    """One window of frames, the machine's second passing before its last one."""
    for i in range(WINDOW_FRAMES):
        if i == WINDOW_FRAMES - 1:
            m.window(others, **kw)
        k.frame(other_tid=4242)


def test_threads_are_kept_on_the_last_two_cores_when_the_machine_is_otherwise_quiet() -> None:
    m = Machine()
    k = keeper(m, {0, 1, 2, 3})
    k.frame(other_tid=0)  # the second thread has not started: nothing to do
    assert not k.kept and m.sets == []
    k.frame(other_tid=4242)  # the first look only starts the window
    assert not k.kept
    frames(k, m, others=0.2)  # the simulated camera and the autopilot's 0.2 cores
    assert k.kept and m.asked[-1] == {0, 1, 2, 3}  # the load on the process's cores
    assert m.sets == [(threading.get_native_id(), {2}), (4242, {3})]
    k.release()
    assert not k.kept and m.sets[-2:] == [(threading.get_native_id(), {0, 1, 2, 3}),
                                         (4242, {0, 1, 2, 3})]


def test_another_busy_process_keeps_them_free_and_frees_them_when_it_starts() -> None:
    m = Machine()
    k = keeper(m)
    k.frame(other_tid=4242)
    frames(k, m, others=1.0)  # a busy loop
    assert not k.kept and m.sets == []
    frames(k, m, others=0.1)
    assert k.kept
    frames(k, m, others=MAX_OTHERS_CORES + 0.2)
    assert not k.kept and m.sets[-1] == (4242, {0, 1}) and k.released == 1
    frames(k, m, others=0.1)  # it has stopped: kept again at the next look
    assert k.kept


def test_kept_threads_that_wait_for_their_cores_go_free_for_a_while() -> None:
    m = Machine()
    k = keeper(m)
    k.frame(other_tid=4242)
    frames(k, m, others=0.1)
    assert k.kept
    frames(k, m, others=0.1, run_ms=400.0, wait_ms=100.0)  # 25 % of their time queued
    assert not k.kept and k.released == 1
    for _ in range(PAUSE_WINDOWS - 1):
        frames(k, m, others=0.1)
        assert not k.kept
    frames(k, m, others=0.1)
    assert k.kept


def test_one_core_or_no_statistics_keep_nothing() -> None:
    m = Machine()
    k = keeper(m, {3})
    for _ in range(3):
        frames(k, m, others=0.0)
    assert not k.kept and m.sets == [] and k.pair is None

    reads: list[int] = []

    def missing(tid: int) -> None:
        reads.append(tid)

    blind = CoreKeeper({0, 1}, read=missing, set_cores=m.set_cores, load=m.load,
                       any_thread=True)
    for _ in range(3 * WINDOW_FRAMES):
        blind.frame(other_tid=4242)
    assert not blind.kept and m.sets == []
    assert len(reads) == 2 * 3  # both threads, once a window: not every frame


def test_a_core_taken_away_leaves_them_free_for_good() -> None:
    m = Machine()

    def refuse(tid: int, allowed: set[int]) -> None:
        if len(allowed) == 1:
            raise OSError(22, "Invalid argument")
        m.set_cores(tid, allowed)

    k = CoreKeeper({0, 1}, read=m.read, set_cores=refuse, load=m.load, any_thread=True)
    k.frame(other_tid=4242)
    frames(k, m, others=0.0)
    assert not k.kept and k.pair is None
    frames(k, m, others=0.0)
    assert not k.kept


def test_the_main_thread_is_never_kept_but_a_worker_thread_is() -> None:
    """A benchmark or a test driving the perception on the main thread keeps nothing (the
    processes it starts would inherit one core); the flight's worker thread is kept."""
    m = Machine()
    k = CoreKeeper({0, 1}, read=m.read, set_cores=m.set_cores, load=m.load)
    k.frame(other_tid=4242)
    frames(k, m, others=0.0)
    assert not k.kept and m.sets == []
    def fly() -> None:
        for _ in range(2):
            frames(k, m, others=0.0)

    worker = threading.Thread(target=fly)
    worker.start()
    worker.join()
    assert k.kept and m.sets[0][0] == worker.native_id


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux's /proc")
def test_the_kernels_statistics_are_read() -> None:
    tid = threading.get_native_id()
    run_wait = cores.schedstat(tid)
    assert run_wait is not None and run_wait[0] > 0
    load = cores.machine_load()
    assert load is not None and 0 <= load[0] <= load[1] and load[3] >= 0
    assert 1 <= load[2] <= (os.cpu_count() or 1)
    assert cores.schedstat(2**31 - 1) is None  # no such thread
    assert cores.process_cores() == set(os.sched_getaffinity(os.getpid()))



class Board:
    """A board's ``/proc/stat`` (the online cores' lines) and this process's
    ``/proc/self/stat`` written to files, a second at a time: ``busy`` ticks (of 100) per
    online core, ``own`` of them this process's."""

    def __init__(self, folder: Path, online: list[int]) -> None:
        self.stat, self.own_file, self.online = folder / "stat", folder / "own", online
        self.seconds, self.busy, self.own = 0, [0] * len(online), 0
        self.second([0] * len(online), own=0)

    def second(self, busy: list[int], own: int) -> None:
        self.seconds += 1
        self.busy = [a + b for a, b in zip(self.busy, busy, strict=True)]
        self.own += own
        rows = [f"cpu{c} {b} 0 0 {100 * self.seconds - b} 0 0 0 0 0 0"
                for c, b in zip(self.online, self.busy, strict=True)]
        idle = 100 * len(self.online) * self.seconds - sum(self.busy)
        self.stat.write_text("\n".join([f"cpu  {sum(self.busy)} 0 0 {idle} 0 0 0 0 0 0",
                                         *rows, "intr 1 2 3", ""]))
        self.own_file.write_text(f"4242 (python3) S {'0 ' * 10}{self.own} 0 0 0\n")

    def load(self, which: set[int] | None) -> tuple[int, int, int, int] | None:
        return cores.machine_load(which, stat=str(self.stat), own=str(self.own_file))


def test_the_load_counted_is_on_the_process_own_cores(tmp_path: Path) -> None:
    """A board giving the companion cores 1-4 (systemd's ``CPUAffinity=1 2 3 4``), core 2
    offline: a camera driver busy on core 0 does not free the frame threads; a process busy
    on the companion's online cores does, by its share of those three cores."""
    board, m = Board(tmp_path, online=[0, 1, 3, 4]), Machine()
    k = CoreKeeper({1, 2, 3, 4}, read=m.read, set_cores=m.set_cores, load=board.load,
                   any_thread=True)

    def window(busy: list[int], own: int) -> None:
        for i in range(WINDOW_FRAMES):
            if i == WINDOW_FRAMES - 1:
                m.window(0.0)
                board.second(busy, own)
            k.frame(other_tid=4242)

    k.frame(other_tid=4242)
    window([100, 40, 40, 40], own=120)  # core 0 the driver's; 1, 3, 4 all ours
    assert k.kept and m.sets[-1] == (4242, {4})
    window([100, 40, 40, 100], own=120)  # another process: 0.6 of core 4
    assert not k.kept and k.released == 1
    window([100, 40, 40, 85], own=120)  # 0.45 of a core over three cores read: kept again
    assert k.kept
    whole = cores.machine_load(None, stat=str(board.stat), own=str(board.own_file))
    assert whole is not None and whole[2] == 4  # every online core's line when no set
    assert board.load({2, 7}) is None  # no such core online: no reading
    assert board.load(set()) is None  # no core at all: not the whole machine


def test_the_threads_follow_the_process_when_its_cores_change() -> None:
    """``taskset`` (or a cgroup) moves the process from cores 0-3 to 4-5: the kept threads
    are let go onto the new cores at the next look and kept on 4 and 5 a window later."""
    m, now = Machine(), [{0, 1, 2, 3}]
    k = CoreKeeper(read=m.read, set_cores=m.set_cores, load=m.load, any_thread=True,
                   process=lambda: set(now[0]))
    k.frame(other_tid=4242)
    frames(k, m, others=0.1)
    assert k.kept and m.sets[-1] == (4242, {3})
    now[0] = {4, 5}
    frames(k, m, others=0.0)
    assert not k.kept and m.sets[-1] == (4242, {4, 5}) and k.pair == (4, 5)
    frames(k, m, others=0.1)  # a window on the new cores' load first: the readings of
    assert not k.kept  # cores 0-3 and 4-5 are not compared (here they would say "keep")
    frames(k, m, others=0.1)
    assert k.kept and m.sets[-2:] == [(threading.get_native_id(), {4}), (4242, {5})]
    assert m.asked[-1] == {4, 5}
