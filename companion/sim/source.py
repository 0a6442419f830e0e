"""The simulated camera as a :class:`~companion.sources.base.FrameSource`."""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import multiprocessing
import resource
import time
from collections import OrderedDict
from multiprocessing import shared_memory

import numpy as np

from companion.core.frames import EndOfStream, Frame, ImageU8, SourceStatus, monotonic_us
from companion.core.stream_format import FrameTruth
from companion.sim.scenario import ScenarioConfig
from companion.sim.simulator import Simulator
from tracker.camera import CameraModel

log = logging.getLogger(__name__)

TRUTH_KEPT = 256
#: The next frame is rendered ahead, starting its expected render time plus this margin
#: before it is due -- not at once: rendering then stays off the cores while the pipeline
#: works on the frame before (a real camera exposes without the companion's CPU).  In one
#: run it took the demo's capture -> wire p99 from 20.6-21.2 to 16.3-16.5 ms (docs/decisions.md).
RENDER_MARGIN_S = 0.004
#: How fast the expected render time (a decaying maximum of the last ones) forgets.
RENDER_TIME_DECAY = 0.95


class OfSimulatedWorld:
    """What a camera of a simulated world (``self.sim``) says it knows beyond its frames
    (the protocols of :mod:`companion.sources.base`)."""

    sim: Simulator

    def reference_images(self) -> dict[str, ImageU8]:
        """The world's landmark textures (:class:`companion.sources.base.KnowsReferences`)."""
        return self.sim.reference_images()

    def camera_model(self) -> CameraModel:
        """The scenario's camera (:class:`companion.sources.base.KnowsCamera`)."""
        return self.sim.scenario.camera


class SimCameraSource(OfSimulatedWorld):
    """Frames from a :class:`Simulator`, rendered off the event loop.

    ``realtime``: frame k is due at ``t0 + k / fps`` on the monotonic clock and carries
    ``t_us = t0_us + k * 1e6 / fps``; when rendering falls behind, the frames that were
    missed are skipped (counted as ``late``) like a live camera drops them.  Otherwise
    frames come as fast as they render with ``t0_us = 0`` (the scenario clock).  Either
    way ``(t_us - t0_us) / 1e6`` is the scenario time to give to ``state_at``.
    ``seconds`` (default: the scenario's) ends the stream; ``loop`` replays it instead.

    ``t0_us`` anchors scenario time 0 to a given monotonic time (realtime only), so that the
    camera and the fake autopilot share one clock: pass the autopilot's start time
    (``FakeAutopilot._start_ns // 1000`` or the app's equivalent).  The first frame is then
    the one due now.

    ``own_process``: render in a process of its own (started here, stopped by
    :meth:`close`), as a real camera exposes without the companion's interpreter.  In this
    process the renderer (mostly Python) holds the GIL for 5-10 ms per frame against the
    companion's threads; issue 23's profile found a third of the demo's samples there
    (docs/benchmarks.md, "Latency tail").  Its CPU is then not the companion's, and
    ``render_cpu_s`` stays 0 and ``render_cpu_elsewhere_s`` adds it up.
    """

    def __init__(
        self,
        simulator: Simulator,
        *,
        realtime: bool = True,
        loop: bool = False,
        seconds: float | None = None,
        t0_us: int | None = None,
        own_process: bool = False,
    ) -> None:
        self.sim = simulator
        self.realtime = realtime
        self.loop = loop
        self.seconds = simulator.scenario.seconds if seconds is None else seconds
        self.camera_id = simulator.scenario.camera_id
        self.status = SourceStatus()
        self.t0_us: int | None = t0_us if realtime else 0
        self._next = 0
        self._frames_per_pass = max(1, round(self.seconds * simulator.fps))
        self._truth: OrderedDict[int, FrameTruth] = OrderedDict()
        self._closed = False
        self._prefetch: tuple[int, asyncio.Future[tuple[ImageU8, FrameTruth]]] | None = None
        self.render_cpu_s = 0.0
        self._render_wall_s = 1.0 / simulator.fps  # expected render time (decaying max)
        self.render_cpu_elsewhere_s = 0.0
        self._process: concurrent.futures.ProcessPoolExecutor | None = None
        self._slots: shared_memory.SharedMemory | None = None
        if own_process:  # spawned, not forked: this process runs threads (Zenoh's too)
            camera = simulator.scenario.camera
            self._slots = _frame_slots(FRAME_SLOTS * camera.height * camera.width * 3)
            self._process = concurrent.futures.ProcessPoolExecutor(
                1, multiprocessing.get_context("spawn"), initializer=_start_renderer,
                initargs=(simulator.scenario, None if self._slots is None else self._slots.name))

    async def start(self) -> None:
        """Wait until the rendering process renders (it imports and builds its world
        first): call before the camera's clock starts.  Nothing to do in this process."""
        if self._process is not None:
            loop = asyncio.get_running_loop()
            await loop.run_in_executor(self._process, _render_elsewhere, 0, 0.0, None)

    def anchor(self, t0_us: int) -> None:
        """Scenario time 0 is ``t0_us`` on the monotonic clock (see ``t0_us`` above)."""
        self.t0_us = t0_us

    def truth(self, index: int) -> FrameTruth | None:
        """Truth of a recent frame (the last few hundred are kept)."""
        return self._truth.get(index)

    def scenario_time_s(self, frame: Frame) -> float:
        """The scenario time of a frame of this source."""
        return (frame.t_us - (self.t0_us or 0)) / 1e6

    def truth_position(self, frame: Frame) -> tuple[float, float, float] | None:
        """Where the vehicle truly was when ``frame`` was taken (flight NED, m):
        :class:`companion.sources.base.KnowsTruth`."""
        state = self.sim.state_at(self.scenario_time_s(frame))
        n, e, d = (float(v) for v in state.position_ned_m)
        return (n, e, d)


    async def recv(self) -> Frame:
        """Render and return the next frame (EndOfStream after ``seconds`` unless looping).

        In real time the next frame is rendered ahead while the pipeline works on this
        one (a camera exposes and reads out while the computer processes), so a frame is
        delivered at its due time instead of a render time later.
        """
        if self._closed:
            raise EndOfStream("source closed")
        index = self._next
        if self.realtime:
            index = await self._wait_due(index, deliver=False)
        if index >= self._frames_per_pass and not self.loop:
            raise EndOfStream("end of scenario")
        self._next = index + 1
        image, truth = await self._rendered(index)
        if self.realtime:
            await self._wait_due(index, deliver=True)
            if self._next < self._frames_per_pass or self.loop:
                ahead = asyncio.ensure_future(self._render_when_due(self._next))
                self._prefetch = (self._next, ahead)
        self._truth[index] = truth
        while len(self._truth) > TRUTH_KEPT:
            self._truth.popitem(last=False)
        self.status.delivered += 1
        t_us = (self.t0_us or 0) + round(index * 1e6 / self.sim.fps)
        return Frame(index, t_us, image, self.camera_id)

    def _render_async(self, index: int) -> asyncio.Future[tuple[ImageU8, FrameTruth]]:
        t_s = (index % self._frames_per_pass) / self.sim.fps
        loop = asyncio.get_running_loop()
        if self._process is not None:
            return asyncio.ensure_future(self._render_there(loop, index, t_s))
        return loop.run_in_executor(None, self._render_timed, index, t_s)

    async def _render_there(self, loop: asyncio.AbstractEventLoop, index: int, t_s: float
                            ) -> tuple[ImageU8, FrameTruth]:
        assert self._process is not None
        slot = None if self._slots is None else index % FRAME_SLOTS
        piped, shape, truth, took, cpu_s = await loop.run_in_executor(
            self._process, _render_elsewhere, index, t_s, slot)
        if piped is not None:
            image = piped
        elif self._slots is None or slot is None:  # closed while it was being rendered
            raise asyncio.CancelledError
        else:
            image = _from_slot(self._slots, slot, shape).copy()
        self.render_cpu_elsewhere_s += cpu_s
        self._render_wall_s = max(RENDER_TIME_DECAY * self._render_wall_s, took)
        return image, truth

    async def _render_when_due(self, index: int) -> tuple[ImageU8, FrameTruth]:
        """Render frame ``index``, starting just early enough to have it when it is due."""
        assert self.t0_us is not None
        due_us = self.t0_us + index * 1e6 / self.sim.fps
        delay_s = (due_us - monotonic_us()) / 1e6 - self._render_wall_s - RENDER_MARGIN_S
        if delay_s > 0:
            await asyncio.sleep(delay_s)
        return await self._render_async(index)

    def _render_timed(self, index: int, t_s: float) -> tuple[ImageU8, FrameTruth]:
        """Render, adding the CPU time it took to ``render_cpu_s`` (the simulated camera is
        not the companion: the demo reports the companion's CPU without it)."""
        start, wall = time.thread_time(), time.monotonic()
        try:
            return self.sim.render(index, t_s)
        finally:
            self.render_cpu_s += time.thread_time() - start
            took = time.monotonic() - wall
            self._render_wall_s = max(RENDER_TIME_DECAY * self._render_wall_s, took)

    async def _rendered(self, index: int) -> tuple[ImageU8, FrameTruth]:
        if self._prefetch is not None and self._prefetch[0] == index:
            future = self._prefetch[1]
        else:
            if self._prefetch is not None:  # fell behind: that frame's time has passed
                self._prefetch[1].cancel()
            future = self._render_async(index)
        self._prefetch = None
        return await future

    async def _wait_due(self, index: int, deliver: bool) -> int:
        """Skip frames whose time has passed (counted late); with ``deliver``, sleep until
        frame ``index`` is due."""
        now = monotonic_us()
        if self.t0_us is None:
            self.t0_us = now
        period_us = 1e6 / self.sim.fps
        if not deliver:
            current = int((now - self.t0_us) // period_us)
            if self.status.delivered == 0 and self.status.skipped == 0:
                return max(index, current)  # the first frame is the one due now
            # behind: drop the frames whose time has passed
            return self.status.catch_up(index, current, f"rendering fell behind at frame {index}")
        delay_s = (self.t0_us + index * period_us - monotonic_us()) / 1e6
        if delay_s > 0:
            await asyncio.sleep(delay_s)
        return index

    def close(self) -> None:
        """Stop delivering (and the rendering process); a frame being rendered ahead is
        cancelled, not left to fail on the slots closed under it."""
        self._closed = True
        if self._prefetch is not None:
            self._prefetch[1].cancel()
            self._prefetch = None
        if self._process is not None:
            self._process.shutdown(wait=False, cancel_futures=True)
        if self._slots is not None:  # the renderer's mapping goes with its process
            self._slots.close()
            self._slots.unlink()
            self._slots = None


#: Frames come back from the rendering process through shared memory, in as many slots as
#: can be in flight (the frame being read and the one rendered ahead), not pickled through a
#: pipe: the pipe cost the companion's process 1.5 ms of CPU a frame (issue 23).
FRAME_SLOTS = 2

_RENDERER: list[tuple[Simulator, shared_memory.SharedMemory | None]] = []  # the renderer's


def _frame_slots(size: int) -> shared_memory.SharedMemory | None:
    """The frame slots' shared memory; None (frames then come pickled through the pool's
    pipe) where the process may not make a file that large (``RLIMIT_FSIZE``: shared
    memory is a file in /dev/shm) or the system refuses it."""
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY and soft < size:
        log.info("demo camera: frames through a pipe (file size limit %d bytes)", soft)
        return None
    try:
        return shared_memory.SharedMemory(create=True, size=size)
    except OSError as exc:
        log.info("demo camera: frames through a pipe (no shared memory: %s)", exc)
        return None


def _from_slot(slots: shared_memory.SharedMemory, slot: int, shape: tuple[int, ...]) -> ImageU8:
    """A view of frame slot ``slot`` as an image of ``shape``."""
    size = int(np.prod(shape))
    return np.ndarray(shape, np.uint8, buffer=slots.buf, offset=slot * size)


def _start_renderer(scenario: ScenarioConfig, slots_name: str | None) -> None:
    # the creator unlinks the block.  Mapping it registers it again with the resource
    # tracker, which a spawned process shares with its parent (a set: no second entry),
    # so it is not unregistered here: that would take the parent's entry away
    slots = None if slots_name is None else shared_memory.SharedMemory(slots_name)
    _RENDERER[:] = [(Simulator(scenario), slots)]


def _render_elsewhere(index: int, t_s: float, slot: int | None
                      ) -> tuple[ImageU8 | None, tuple[int, ...], FrameTruth, float, float]:
    """In the rendering process: frame ``index`` into frame slot ``slot`` (None: no slots,
    the image is returned); the image or None, its shape, truth, and the wall and CPU time
    it took."""
    wall, cpu = time.monotonic(), time.process_time()
    simulator, slots = _RENDERER[0]
    image, truth = simulator.render(index, t_s)
    piped: ImageU8 | None = image
    if slots is not None and slot is not None:
        _from_slot(slots, slot, image.shape)[...] = image
        piped = None
    return piped, image.shape, truth, time.monotonic() - wall, time.process_time() - cpu
