"""The frame contract shared by every source, status counters and replay pacing."""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

ImageU8 = npt.NDArray[np.uint8]


@dataclass(frozen=True, eq=False)
class Frame:
    """One camera frame.

    ``index``: position in the source (0-based, increasing).  ``t_us``: capture time in
    microseconds on the companion's monotonic clock (recorded streams keep their own times).
    ``image``: HxWx3 BGR uint8.  ``camera_id``: which camera took it.
    """

    index: int
    t_us: int
    image: ImageU8
    camera_id: str = "cam0"

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return int(self.image.shape[1]), int(self.image.shape[0])


class EndOfStream(EOFError):  # noqa: N818  (a normal end, not an error)
    """Raised by :meth:`FrameSource.recv` when a finite source has no more frames.

    An :class:`EOFError`, which is what the pipeline (``companion.app``) waits for.
    """


@dataclass
class SourceStatus:
    """Counters a source keeps; the pipeline publishes them in its status.

    ``skipped`` counts frames dropped mid-stream (unreadable, wrong size, time going
    backwards), with a count per reason in ``skip_reasons``; ``dropped`` counts good frames
    of a live source replaced by a newer one before they were taken; ``stalls`` counts stall
    timeouts of a live source; ``last_error`` is the latest one-line problem.
    """

    delivered: int = 0
    skipped: int = 0
    dropped: int = 0
    stalls: int = 0
    loops: int = 0
    skip_reasons: dict[str, int] = field(default_factory=dict)
    last_error: str = ""

    def skip(self, reason: str, detail: str) -> None:
        """Count one skipped frame for ``reason`` and remember ``detail``."""
        self.skipped += 1
        self.skip_reasons[reason] = self.skip_reasons.get(reason, 0) + 1
        self.last_error = detail

    def as_dict(self) -> dict[str, object]:
        """Plain dict for JSON status messages."""
        return {
            "delivered": self.delivered,
            "skipped": self.skipped,
            "dropped": self.dropped,
            "stalls": self.stalls,
            "loops": self.loops,
            "skip_reasons": dict(self.skip_reasons),
            "last_error": self.last_error,
        }


@runtime_checkable
class FrameSource(Protocol):
    """What the pipeline needs from a source."""

    status: SourceStatus

    async def recv(self) -> Frame:
        """The next frame; raises :class:`EndOfStream` at the end of a finite source."""
        ...

    def close(self) -> None:
        """Release files, devices and threads (idempotent)."""
        ...


def monotonic_us() -> int:
    """The companion's monotonic clock in microseconds."""
    return time.monotonic_ns() // 1000


class Pacer:
    """Replays recorded times at their original pace (``realtime``) or as fast as possible.

    The first paced time is anchored to the wall clock; later ones wait until
    ``anchor_wall + (t_us - anchor_t_us) / speed``.
    """

    def __init__(self, realtime: bool, speed: float = 1.0) -> None:
        if speed <= 0:
            raise ValueError(f"speed: expected > 0, got {speed}")
        self.realtime = realtime
        self.speed = speed
        self._anchor: tuple[int, int] | None = None  # (recorded t_us, wall us)

    def reset(self) -> None:
        """Re-anchor on the next frame (after a loop or a seek)."""
        self._anchor = None

    async def wait(self, t_us: int) -> None:
        """Sleep until recorded time ``t_us`` is due."""
        if not self.realtime:
            return
        now = monotonic_us()
        if self._anchor is None:
            self._anchor = (t_us, now)
            return
        due = self._anchor[1] + (t_us - self._anchor[0]) / self.speed
        delay_s = (due - now) / 1e6
        if delay_s > 0:
            await asyncio.sleep(delay_s)
