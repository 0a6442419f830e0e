"""The soak's memory checks (testsupport/soak.py): what it reads of a process's resident
memory, and how its verdict treats a transient buffer against growth."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator

import psutil
import pytest

from testsupport.soak import MemoryWatch, Sample, verdict

#: A child that, on each line it reads, holds 40 MB for 30 ms and gives it back (more than
#: glibc's largest mmap threshold, so freeing it returns it to the system).
CHILD = """
import sys, time
print("ready", flush=True)
for _ in sys.stdin:
    block = b"x" * (40 * 2**20)
    time.sleep(0.03)
    del block
    print("done", flush=True)
"""


@pytest.fixture
def child() -> Iterator[subprocess.Popen[str]]:
    proc = subprocess.Popen([sys.executable, "-c", CHILD], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
    yield proc
    proc.kill()
    proc.wait(5)
    for pipe in (proc.stdin, proc.stdout):
        if pipe is not None:
            pipe.close()


def spike(proc: subprocess.Popen[str]) -> None:
    assert proc.stdin is not None and proc.stdout is not None
    proc.stdin.write("go\n")
    proc.stdin.flush()
    assert proc.stdout.readline() == "done\n"


def interval(watch: MemoryWatch, reads: int) -> tuple[float, float]:
    for _ in range(reads):
        watch.read()
        time.sleep(0.02)
    floor, peak, exact = watch.close()
    assert exact, "the interval's peak is not the kernel's high-water mark"
    return floor, peak


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="VmHWM is Linux's")
def test_watch_sees_a_transient_between_reads_and_restarts(
        child: subprocess.Popen[str]) -> None:
    watch = MemoryWatch(child.pid)
    assert watch.exact, "could not restart the child's VmHWM through /proc/PID/clear_refs"
    watch.read()
    spike(child)  # between two reads: only the kernel's high-water mark sees it
    floor, peak = interval(watch, 3)
    assert peak - floor > 35.0, (floor, peak)
    floor2, peak2 = interval(watch, 3)  # no transient in this interval
    assert peak2 - floor2 < 5.0, (floor2, peak2)
    assert abs(floor2 - floor) < 5.0, (floor, floor2)


def test_a_zombie_is_a_process_gone() -> None:
    """An exited child not yet reaped reads 0 MB through psutil: that must end the watch,
    not become the last interval's floor (a -100 % growth that passes)."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    try:
        watch = MemoryWatch(proc.pid)
        deadline = time.monotonic() + 10.0
        while psutil.Process(proc.pid).status() != psutil.STATUS_ZOMBIE:
            assert time.monotonic() < deadline, "the child did not exit"
            time.sleep(0.01)
        with pytest.raises(psutil.Error):
            watch.read()
    finally:
        proc.wait(5)


def samples(floors: list[float], peaks: list[float], exact: bool = True) -> list[Sample]:
    pairs = zip(floors, peaks, strict=True)
    return [Sample(float(i), f, p, 19, 10, 45, exact) for i, (f, p) in enumerate(pairs)]


def test_a_constant_transient_is_not_growth() -> None:
    """Every interval holds 32 MB for a moment (feature matching): the floor is flat, the
    peaks too: ok -- where point samples that caught it now and then read +13 %."""
    out = verdict(samples([241.0] * 15, [273.0, 241.2, 273.1] * 5), 15.0, warm_up_s=0.0)
    assert out["ok"], out
    assert out["rss_growth_pct"] == 0.0 and out["rss_peak_growth_pct"] < 0.1


def test_a_rising_floor_fails() -> None:
    floors = [241.0 + 1.0 * i for i in range(15)]  # +14 MB: +5.8 %
    out = verdict(samples(floors, [f + 32.0 for f in floors]), 15.0, warm_up_s=0.0)
    assert not out["ok"] and out["rss_growth_pct"] > 5.0, out


def test_a_growing_transient_fails() -> None:
    """The floor flat, but the peak in the last third 20 MB over the first third's (a
    backlog that builds): the peak check fails it."""
    peaks = [273.0] * 10 + [293.0] * 5
    out = verdict(samples([241.0] * 15, peaks), 15.0, warm_up_s=0.0)
    assert not out["ok"] and out["rss_peak_growth_pct"] > 5.0, out


def test_peaks_without_the_high_water_mark_are_reported_not_judged() -> None:
    """Where VmHWM cannot be restarted the peaks are the highest of reads every 0.25 s:
    the first third caught no transient, a later one did.  Reported, not failed; the floor
    is still judged."""
    peaks = [241.2] * 5 + [273.0, 241.2, 241.3] * 3 + [241.2]
    out = verdict(samples([241.0] * 15, peaks, exact=False), 15.0, warm_up_s=0.0)
    assert out["rss_peak_growth_pct"] > 5.0 and not out["rss_peak_exact"]
    assert out["ok"], out
    rising = [241.0 + i for i in range(15)]
    assert not verdict(samples(rising, rising, exact=False), 15.0, warm_up_s=0.0)["ok"]


def test_the_picture_draws_floor_and_peak() -> None:
    """The soak's picture: both lines drawn (the palette's first two colours present),
    the verdict in its title's pixels not checked (text)."""
    from companion.evaluation.plots import PALETTE
    from testsupport.soak import plot

    floors = [241.0 + 0.01 * i for i in range(15)]
    peaks = [273.0, 241.2, 273.1] * 5
    ss = samples(floors, peaks)
    result = {"seconds": 45.0, "samples": [s.__dict__ for s in ss],
              "verdict": verdict(ss, 45.0, warm_up_s=3.0)}
    img = plot(result)
    assert img.shape == (400, 800, 3)
    for colour in PALETTE[:2]:
        assert (img == colour).all(axis=2).sum() > 50, colour
