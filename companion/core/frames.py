"""The records a frame source and the simulator share: a frame, its image type, a
source's counters, the end of a finite stream and the companion's monotonic clock."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

ImageU8 = npt.NDArray[np.uint8]


@dataclass(frozen=True, eq=False)
class Frame:
    """One camera frame.

    ``index``: position in the source (0-based, increasing).  ``t_us``: capture time in
    microseconds on the companion's monotonic clock (recorded streams keep their own times).
    ``image``: HxWx3 BGR uint8.  ``camera_id``: which camera took it.  ``lossy``: the
    image passed through a lossy codec (a JPEG file, a video, a network stream) on its way
    here, which moves edges (docs/decisions.md, "A plate's modes on lossy frames").
    """

    index: int
    t_us: int
    image: ImageU8
    camera_id: str = "cam0"
    lossy: bool = False

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return int(self.image.shape[1]), int(self.image.shape[0])


class EndOfStream(EOFError):  # noqa: N818  (a normal end, not an error)
    """Raised by ``FrameSource.recv`` (:mod:`companion.sources.base`) when a finite source
    has no more frames.

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

    def catch_up(self, index: int, due_now: int, detail: str) -> int:
        """The frame to take next when frame ``index`` is next and ``due_now`` is due:
        the ones between were not read in time and are gone, as a live camera's are
        (each counted skipped as ``late``)."""
        for _ in range(index, due_now):
            self.skip("late", detail)
        return max(index, due_now)

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


def monotonic_us() -> int:
    """The companion's monotonic clock in microseconds."""
    return time.monotonic_ns() // 1000
