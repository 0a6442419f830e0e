"""The soak: a long simulated flight of the real ``companion run`` process, watched for
leaks (benchmarks/soak.py is its command line and says what it checks; sitl_tests/test_soak.py
runs a 75 s form of the same checks).

Resident memory is watched between samples, not only at them: feature matching (SIFT on the
whole frame, every ``acquire_every_frames_with_fix`` frames) holds ~32 MB for ~50 ms and gives
it back, and samples every 3 s caught that transient at every third match (a 4 s period
against 3 s samples), reading it as growth (docs/reliability.md, "Transient memory").  So each
sample has the interval's floor (what the process keeps between such buffers: a leak raises
it) and its peak (Linux's exact VmHWM, restarted every interval)."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import statistics
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import psutil

from companion.evaluation.plots import Series, line_plot
from companion.sim.scenario import SCENARIO_DIR, load_scenario
from companion.sim.simulator import Simulator
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from testsupport.flightconfig import run_config as flight_run_config

ROOT = Path(__file__).resolve().parents[1]
#: How often resident memory is read between samples (for the interval's floor).
POLL_S = 0.25
MB = 2**20


class MemoryWatch:
    """A process's resident memory over one interval: the floor of reads every POLL_S, and
    the peak -- on Linux the kernel's high-water mark (VmHWM, restarted through
    ``/proc/PID/clear_refs`` at each interval's start, so no transient slips between
    reads); where that is not possible, the highest read."""

    def __init__(self, pid: int) -> None:
        self.process = psutil.Process(pid)
        self.proc_dir = Path(f"/proc/{pid}")
        self.floor = self.peak = 0.0
        self.exact = False
        self.restart()

    def restart(self) -> None:
        """A new interval starts now."""
        self.floor, self.peak = float("inf"), 0.0
        try:
            (self.proc_dir / "clear_refs").write_text("5", encoding="ascii")
            self.exact = True
        except OSError:
            self.exact = False

    def read(self) -> None:
        """One read of resident memory (psutil.Error when the process has gone: a zombie,
        whose memory psutil reads as 0 before it is reaped, included)."""
        rss = self.process.memory_info().rss / MB
        if rss <= 0.0 or self.process.status() == psutil.STATUS_ZOMBIE:
            raise psutil.NoSuchProcess(self.process.pid)
        self.floor, self.peak = min(self.floor, rss), max(self.peak, rss)

    def close(self) -> tuple[float, float, bool]:
        """The interval's floor and peak in MB, and whether that peak is the kernel's
        high-water mark; the next interval starts."""
        self.read()
        floor, peak, exact = self.floor, self.peak, self.exact
        if exact:
            peak = max(peak, high_water_mb(self.proc_dir / "status") or 0.0)
        self.restart()
        return floor, peak, exact


def high_water_mb(status: Path) -> float | None:
    """VmHWM of a ``/proc/PID/status`` file in MB (None when it has none or is gone)."""
    try:
        text = status.read_text(encoding="ascii")
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return None


@dataclass(frozen=True)
class Sample:
    t_s: float
    rss_mb: float  # the interval's floor: the lowest of the polls every POLL_S
    rss_peak_mb: float  # the interval's peak (VmHWM on Linux, else the highest poll)
    fds: int
    threads: int
    fused: int  # fixes fused by the autopilot in this interval
    rss_peak_exact: bool = True  # the peak is VmHWM's (False: the highest poll)


def soak_scenario(tmp: Path, seconds: float, fps: float) -> Path:
    """The hover scenario, ``seconds`` long at ``fps``, as a file (landmarks by absolute
    path; the simulated camera takes its rate from the scenario)."""
    text = (SCENARIO_DIR / "hover.toml").read_text(encoding="utf-8")
    text = re.sub(r"(?m)^seconds = .*$", f"seconds = {seconds:.1f}", text)
    text = re.sub(r"(?m)^fps = .*$", f"fps = {fps:.1f}", text)
    text = re.sub(r'(?m)^landmarks = .*$',
                  f'landmarks = "{(ROOT / "config" / "landmarks.geojson").as_posix()}"', text)
    path = tmp / "soak.toml"
    path.write_text(text, encoding="utf-8")
    return path


def run_config(tmp: Path, scenario: Path, port: int) -> Path:
    """``companion run``'s config for the soak (the same builder the scenario tests use)."""
    return flight_run_config(tmp, port, scenario=scenario.as_posix(),
                              extra="[logging]\nlevel = \"warning\"\n", name="soak-run.toml")


async def soak(seconds: float, sample_s: float = 5.0, fps: float = 15.0,
               tmp: Path | None = None, thread_slack: int = 0,
               warm_up_s: float | None = None) -> dict[str, Any]:
    """Fly ``seconds`` and return the samples and the verdicts (``warm_up_s``: see
    :func:`verdict`)."""
    tmp = tmp or Path(tempfile.mkdtemp(prefix="lmc-soak-"))
    scenario = soak_scenario(tmp, seconds + 60.0, fps)
    sim = Simulator(load_scenario(str(scenario)))
    samples: list[Sample] = []
    async with FakeAutopilot(FakeAutopilotConfig(), truth=sim.truth_fn) as fake:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "companion", "--config",
            str(run_config(tmp, scenario, fake.local_port)), "run", "--seconds",
            str(seconds), cwd=tmp, env=env, stderr=asyncio.subprocess.PIPE)
        assert proc.stderr is not None
        err = bytearray()
        # read as it comes: a long flight's log must never fill the pipe and stall it
        reading = asyncio.ensure_future(_drain(proc.stderr, err))
        exited = asyncio.ensure_future(proc.wait())
        try:
            await _watch(proc.pid, exited, fake, samples, seconds + 60, sample_s)
        finally:
            exited.cancel()
            await _stop(proc)
            await asyncio.wait({reading}, timeout=5.0)
            reading.cancel()
    return {"seconds": seconds, "sample_s": sample_s, "fps": fps,
            "exit_status": proc.returncode, "stderr_tail": err.decode(errors="replace")[-500:],
            "samples": [asdict(s) for s in samples],
            "verdict": verdict(samples, seconds, thread_slack, warm_up_s)}


async def _watch(pid: int, exited: asyncio.Future[int], fake: FakeAutopilot,
                 samples: list[Sample], limit_s: float, sample_s: float) -> None:
    """Append a :class:`Sample` every ``sample_s`` until the process exits (or
    ``limit_s``), reading its memory every POLL_S in between."""
    start, seen = time.monotonic(), 0
    next_sample = start + sample_s
    try:
        ps, memory = psutil.Process(pid), MemoryWatch(pid)
        while time.monotonic() - start < limit_s:
            await asyncio.wait({exited}, timeout=POLL_S)
            if exited.done():
                return
            memory.read()
            if time.monotonic() < next_sample:
                continue
            next_sample += sample_s
            floor, peak, exact = memory.close()
            fds, threads = ps.num_fds(), ps.num_threads()
            fused = sum(1 for r in fake.vision[seen:] if r.accepted)
            seen = len(fake.vision)
            samples.append(Sample(round(time.monotonic() - start, 1), round(floor, 2),
                                  round(peak, 2), fds, threads, fused, exact))
    except psutil.Error:  # it ended (or is ending) between the wait and a read
        return


async def _drain(stream: asyncio.StreamReader, into: bytearray, keep: int = 65536) -> None:
    """Read ``stream`` to its end, keeping its last ``keep`` bytes in ``into``."""
    while chunk := await stream.read(4096):
        into += chunk
        del into[:-keep]


async def _stop(proc: asyncio.subprocess.Process, grace_s: float = 30.0) -> None:
    """SIGTERM if still running, then SIGKILL after ``grace_s``; reaped either way."""
    if proc.returncode is None:
        proc.send_signal(signal.SIGTERM)
    try:
        await asyncio.wait_for(proc.wait(), grace_s)
    except TimeoutError:
        proc.kill()
        await proc.wait()


def pct(value: float, reference: float) -> float:
    """``value``'s growth over ``reference`` in per cent, to two decimals."""
    return round(100 * (value - reference) / reference, 2)


def verdict(samples: list[Sample], seconds: float, thread_slack: int = 0,
            warm_up_s: float | None = None) -> dict[str, Any]:
    """The soak's checks on samples after the warm-up (memory: the last interval's floor
    against the first's, and the peak against the first third's peak where the peaks are
    exact -- VmHWM -- else reported only; ``thread_slack``:
    threads the last third may have beyond the first third's peak; the short CI form allows
    1, for a pool thread started late under load; ``warm_up_s``: None = 10 % of the flight,
    at least 15 s)."""
    warm = max(15.0, 0.1 * seconds) if warm_up_s is None else warm_up_s
    after = [s for s in samples if s.t_s >= warm]
    if len(after) < 3:
        return {"ok": False, "reason": f"only {len(after)} samples after warm-up"}
    base = after[0]
    third = max(1, len(after) // 3)
    first, last = after[:third], after[-third:]
    rates = [s.fused for s in after[1:]]
    median = statistics.median(rates)
    half = len(rates) // 2
    first_half, second_half = statistics.median(rates[:half]), statistics.median(rates[half:])
    out: dict[str, Any] = {
        "warm_up_s": warm,
        "rss_mb_at_warm_up": base.rss_mb,
        "rss_mb_last": after[-1].rss_mb,
        "rss_growth_pct": pct(after[-1].rss_mb, base.rss_mb),
        # the peak after warm-up against the first third's: a constant transient (feature
        # matching's buffers) is in both, a growing one or a backlog raises the peak
        "rss_peak_mb_first_third": max(s.rss_peak_mb for s in first),
        "rss_peak_mb": max(s.rss_peak_mb for s in after),
        "rss_peak_growth_pct": pct(max(s.rss_peak_mb for s in after),
                                   max(s.rss_peak_mb for s in first)),
        # judged only where the kernel's high-water mark gave it: the highest of reads
        # every POLL_S misses a 50 ms transient most of the time, so one third can miss
        # every one while another catches one (a false growth)
        "rss_peak_exact": all(s.rss_peak_exact for s in after),
        # pools start threads lazily: growth = the last third's peak over the first third's
        "fds_first_last_third": [max(s.fds for s in first), max(s.fds for s in last)],
        "threads_first_last_third": [max(s.threads for s in first),
                                     max(s.threads for s in last)],
        "fused_per_interval": {"min": min(rates), "median": median, "max": max(rates),
                               "median_first_half": first_half,
                               "median_second_half": second_half},
    }
    peak_ok = out["rss_peak_growth_pct"] <= 5.0 or not out["rss_peak_exact"]
    out["ok"] = bool(out["rss_growth_pct"] <= 5.0 and peak_ok
                     and max(s.fds for s in last) <= max(s.fds for s in first)
                     and max(s.threads for s in last)
                     <= max(s.threads for s in first) + thread_slack
                     and min(rates) > 0 and second_half >= 0.7 * first_half)
    return out


def plot(result: dict[str, Any]) -> npt.NDArray[np.uint8]:
    """The soak's memory as a picture (BGR): each interval's floor and peak over the flight,
    the floor after the warm-up (what is judged) drawn over in a colour of its own."""
    samples = result["samples"]
    t = np.array([s["t_s"] for s in samples], np.float64)
    floor = np.array([s["rss_mb"] for s in samples], np.float64)
    peak = np.array([s["rss_peak_mb"] for s in samples], np.float64)
    v = result["verdict"]
    warm = float(v.get("warm_up_s", 0.0))
    after = t >= warm
    lo = float(np.min(floor[after])) if after.any() else float(np.min(floor))
    hi = float(np.max(peak[after])) if after.any() else float(np.max(peak))
    verdict_text = "ok" if v.get("ok") else "FAILED"
    peak_label = "peak (VmHWM)" if v.get("rss_peak_exact") else "peak (highest read)"
    return line_plot(
        [Series(peak_label, t, peak), Series("floor", t, floor),
         Series("floor, judged", t[after], floor[after])],
        f"soak {result['seconds']:g} s: RSS floor {v.get('rss_growth_pct')} %, "
        f"peak {v.get('rss_peak_growth_pct')} % after {warm:g} s -- {verdict_text}",
        "s", "MB", (0.95 * lo, 1.05 * hi), size=(800, 400))
