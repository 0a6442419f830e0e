"""The simulated camera as a :class:`~companion.sources.base.FrameSource`."""

from __future__ import annotations

import asyncio
from collections import OrderedDict

from companion.sim.simulator import Simulator
from companion.sources.base import EndOfStream, Frame, SourceStatus, monotonic_us
from companion.sources.stream_format import FrameTruth

TRUTH_KEPT = 256


class SimCameraSource:
    """Frames from a :class:`Simulator`, rendered off the event loop.

    ``realtime``: frame k is due at ``t0 + k / fps`` on the monotonic clock and carries
    ``t_us = t0_us + k * 1e6 / fps``; when rendering falls behind, the frames that were
    missed are skipped (counted as ``late``) like a live camera drops them.  Otherwise
    frames come as fast as they render with ``t0_us = 0`` (the scenario clock).  Either
    way ``(t_us - t0_us) / 1e6`` is the scenario time to give to ``state_at``.
    ``seconds`` (default: the scenario's) ends the stream; ``loop`` replays it instead.
    """

    def __init__(
        self,
        simulator: Simulator,
        *,
        realtime: bool = True,
        loop: bool = False,
        seconds: float | None = None,
    ) -> None:
        self.sim = simulator
        self.realtime = realtime
        self.loop = loop
        self.seconds = simulator.scenario.seconds if seconds is None else seconds
        self.camera_id = simulator.scenario.camera_id
        self.status = SourceStatus()
        self.t0_us: int | None = None if realtime else 0
        self._next = 0
        self._frames_per_pass = max(1, round(self.seconds * simulator.fps))
        self._truth: OrderedDict[int, FrameTruth] = OrderedDict()
        self._closed = False

    def truth(self, index: int) -> FrameTruth | None:
        """Truth of a recent frame (the last few hundred are kept)."""
        return self._truth.get(index)

    def scenario_time_s(self, frame: Frame) -> float:
        """The scenario time of a frame of this source."""
        return (frame.t_us - (self.t0_us or 0)) / 1e6

    async def recv(self) -> Frame:
        """Render and return the next frame (EndOfStream after ``seconds`` unless looping)."""
        if self._closed:
            raise EndOfStream("source closed")
        index = self._next
        if self.realtime:
            index = await self._wait_due(index)
        if index >= self._frames_per_pass and not self.loop:
            raise EndOfStream("end of scenario")
        self._next = index + 1
        t_s = (index % self._frames_per_pass) / self.sim.fps
        loop = asyncio.get_running_loop()
        image, truth = await loop.run_in_executor(None, self.sim.render, index, t_s)
        self._truth[index] = truth
        while len(self._truth) > TRUTH_KEPT:
            self._truth.popitem(last=False)
        self.status.delivered += 1
        t_us = (self.t0_us or 0) + round(index * 1e6 / self.sim.fps)
        return Frame(index, t_us, image, self.camera_id)

    async def _wait_due(self, index: int) -> int:
        now = monotonic_us()
        if self.t0_us is None:
            self.t0_us = now
        period_us = 1e6 / self.sim.fps
        current = int((now - self.t0_us) // period_us)
        if current > index:  # behind: drop the frames whose time has passed
            for _ in range(index, current):
                self.status.skip("late", f"rendering fell behind at frame {index}")
            index = current
        due = self.t0_us + index * period_us
        delay_s = (due - monotonic_us()) / 1e6
        if delay_s > 0:
            await asyncio.sleep(delay_s)
        return index

    def close(self) -> None:
        """Stop delivering."""
        self._closed = True
