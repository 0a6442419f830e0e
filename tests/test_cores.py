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
    the cores other processes kept busy."""

    def __init__(self) -> None:
        self.run_ns = self.wait_ns = 0
        self.busy = self.total = self.own = 0
        self.sets: list[tuple[int, set[int]]] = []

    def window(self, others: float, run_ms: float = 500.0, wait_ms: float = 10.0,
               own_cores: float = 0.4) -> None:
        """One second passes on a 2-core machine."""
        self.run_ns += int(run_ms * 1e6)
        self.wait_ns += int(wait_ms * 1e6)
        self.total += 200
        self.own += round(own_cores * 100)
        self.busy += round((own_cores + others) * 100)

    def read(self, tid: int) -> tuple[int, int]:
        return self.run_ns // 2, self.wait_ns // 2  # each thread half

    def load(self) -> tuple[int, int, int]:
        return self.busy, self.total, self.own

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
    assert k.kept
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
    assert load is not None and 0 <= load[0] <= load[1] and load[2] >= 0
    assert cores.schedstat(2**31 - 1) is None  # no such thread
    assert cores.process_cores() == set(os.sched_getaffinity(os.getpid()))



def test_the_load_counted_is_on_the_processs_own_cores(tmp_path: Path) -> None:
    """A 4-core board whose cores 0-1 are busy with other work and 2-3 given to the
    companion (systemd's ``CPUAffinity=``): only cores 2-3's ticks count."""
    stat, own = tmp_path / "stat", tmp_path / "own"

    def second(n: int, busy01: int, busy23: int) -> None:
        """``n`` seconds (100 ticks each) since boot: cores 0-1 and 2-3 busy so many."""
        per_core = [busy01, busy01, busy23, busy23]
        rows = [f"cpu{c} {b} 0 0 {100 * n - b} 0 0 0 0 0 0" for c, b in enumerate(per_core)]
        stat.write_text("\n".join([f"cpu  {sum(per_core)} 0 0 {400 * n - sum(per_core)} "
                                   "0 0 0 0 0 0", *rows, "intr 1 2 3", ""]))
        mine = 2 * busy23  # the companion is all the load on cores 2-3
        own.write_text(f"4242 (python3) S {'0 ' * 10}{mine // 2} {mine - mine // 2} 0 0\n")

    def others(cores_read: set[int] | None) -> int:
        """Other processes' ticks over the second second."""
        second(1, 0, 0)
        before = cores.machine_load(cores_read, stat=str(stat), own=str(own))
        second(2, 100, 40)
        after = cores.machine_load(cores_read, stat=str(stat), own=str(own))
        assert before is not None and after is not None
        return (after[0] - before[0]) - (after[2] - before[2])

    assert others({2, 3}) == 0  # nothing else on the companion's cores
    assert others(None) == 200  # the whole machine: cores 0-1 busy
    assert cores.machine_load({7}, stat=str(stat), own=str(own)) is None  # no such core
