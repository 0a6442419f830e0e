"""The demo's fake autopilot in a process of its own (issue 23).

A real autopilot runs on its own board: its EKF, streams and vision judging cost the
companion nothing.  In one process with the companion, the fake's 10 ms tick (its EKF,
its streams, its parsing of every vision message) ran on the companion's event loop and
counted in its CPU (docs/benchmarks.md, "Latency tail (issue 23)", "Where the CPU goes").
:class:`AutopilotProcess` runs the very same :class:`FakeAutopilot` in a spawned process
and offers what the demo reads of it: ``start``, ``local_port``, ``start_ns`` (on the
machine-wide ``CLOCK_MONOTONIC``, the same clock in both processes), ``accepted()``,
``summary()``, ``stop``, and the CPU time the process used (``cpu_s``), which the demo
reports apart from the companion's.
"""

from __future__ import annotations

import asyncio
import multiprocessing
import multiprocessing.connection
import os
import time
from collections.abc import Iterable
from typing import Any

from companion.errors import CompanionError
from companion.sim.scenario import ScenarioConfig
from mavlink_bridge.fake_autopilot import FakeAutopilot, FakeAutopilotConfig
from mavlink_bridge.fake_rules import VisionRecord

#: How often the process publishes its count of accepted fixes (for the progress line).
COUNT_PERIOD_S = 0.5


class AutopilotProcess:
    """A :class:`FakeAutopilot` flying ``scenario``'s trajectory in a spawned process.

    ``cores``: the CPUs it may run on (``os.sched_setaffinity``; None: as this process).
    Its results (``accepted()``, ``summary()``, ``cpu_s``) are there once :meth:`stop`
    returned; while it runs, :attr:`accepted_count` is at most ``COUNT_PERIOD_S`` old.
    """

    def __init__(self, config: FakeAutopilotConfig, scenario: ScenarioConfig,
                 cores: Iterable[int] | None = None) -> None:
        ctx = multiprocessing.get_context("spawn")  # this process runs threads: never fork
        self._conn, child = ctx.Pipe()
        self._count = ctx.Value("i", 0, lock=False)
        self._process = ctx.Process(target=_serve, name="fake-autopilot", daemon=True,
                                    args=(child, config, scenario,
                                          None if cores is None else set(cores), self._count))
        self._child = child
        self._port = 0
        self._start_ns = 0
        self._result: dict[str, Any] | None = None

    def launch(self) -> None:
        """Start the process: it imports and builds its world, then waits for
        :meth:`start` (so its start-up overlaps the camera's; t = 0 is not yet)."""
        if self._process.pid is None:
            self._process.start()
            self._child.close()  # ours: a dead child then ends recv() with EOFError

    async def start(self) -> None:
        """Create the fake over there (its creation is t = 0); returns once it listens."""
        self.launch()
        self._conn.send("go")
        try:
            self._port, self._start_ns = await asyncio.to_thread(self._conn.recv)
        except EOFError:
            raise CompanionError("the fake autopilot's process ended before it "
                                 "listened") from None

    @property
    def local_port(self) -> int:
        return self._port

    @property
    def start_ns(self) -> int:
        """When the flight began (``truth`` time 0), ``time.monotonic_ns`` (any process)."""
        return self._start_ns

    @property
    def accepted_count(self) -> int:
        """Fixes the fake has fused so far (exact after :meth:`stop`)."""
        return len(self.accepted()) if self._result is not None else int(self._count.value)

    async def stop(self) -> None:
        """Stop the fake and take its results; idempotent."""
        if self._result is not None:
            return
        if not self._process.is_alive():
            raise CompanionError("the fake autopilot's process ended early (exit code "
                                 f"{self._process.exitcode})")
        self._conn.send("stop")
        try:
            self._result = await asyncio.to_thread(self._conn.recv)
        except EOFError:
            raise CompanionError("the fake autopilot's process ended before it "
                                 "reported") from None
        finally:
            await asyncio.to_thread(self._process.join, 5.0)
            self._conn.close()

    def close(self) -> None:
        """End the process at once, results or not (start-up failed)."""
        if self._process.is_alive():
            self._process.terminate()
            self._process.join(5.0)
        self._conn.close()

    def accepted(self) -> list[VisionRecord]:
        return list(self._done()["accepted"])

    def summary(self) -> dict[str, Any]:
        return dict(self._done()["summary"])

    @property
    def cpu_s(self) -> float:
        """CPU time (s) the process used from the flight's start to :meth:`stop`."""
        return float(self._done()["cpu_s"])

    def _done(self) -> dict[str, Any]:
        if self._result is None:
            raise RuntimeError("the fake autopilot's results are there after stop()")
        return self._result


def _serve(conn: multiprocessing.connection.Connection, config: FakeAutopilotConfig,
           scenario: ScenarioConfig, cores: set[int] | None, count: Any) -> None:
    """The process: fly the scenario's truth until told to stop, then report."""
    if cores:
        os.sched_setaffinity(0, cores)
    asyncio.run(_fly(conn, config, scenario, count))


async def _fly(conn: multiprocessing.connection.Connection, config: FakeAutopilotConfig,
               scenario: ScenarioConfig, count: Any) -> None:
    from companion.sim.simulator import Simulator  # the child's own (not the parent's)

    truth = Simulator(scenario).truth_fn
    await asyncio.to_thread(conn.recv)  # "go": the flight's clock starts now
    fake = FakeAutopilot(config, truth=truth)
    await fake.start()
    cpu0 = time.process_time()
    conn.send((fake.local_port, fake.start_ns))
    loop = asyncio.get_running_loop()
    told = asyncio.Event()
    loop.add_reader(conn.fileno(), told.set)
    while not told.is_set():
        count.value = sum(r.accepted for r in fake.vision)
        try:
            await asyncio.wait_for(told.wait(), COUNT_PERIOD_S)
        except TimeoutError:
            pass
    loop.remove_reader(conn.fileno())
    conn.recv()
    await fake.stop()
    conn.send({"accepted": fake.accepted(), "summary": fake.summary(),
               "cpu_s": time.process_time() - cpu0})
    conn.close()
