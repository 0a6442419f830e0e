"""Is the processing keeping up with the camera?  (issue 23)

A frame the worker has not taken when the next one comes is dropped (newest wins,
:class:`companion.pipeline.latest.LatestSlot`): on a board too slow for the settings --
more landmarks at once than its cores can align at the camera's rate, a resolution too
high, another process on the same core -- fixes then come less often and later, and only
the status's ``dropped_frames`` counter said so.  :class:`KeepUpWatch` turns the counts
into a warning: more than ``behind_share`` of the frames of the last ``window_s`` dropped
is "falling behind" (one log line, an event, a STATUSTEXT and a status warning, as a
missing autopilot stream is), at or under ``caught_up_share`` again is "keeping up".
What to lower first on a slower board: docs/deploy.md, "Latency on a slower board".
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class KeepUpPolicy:
    """When dropped frames make a warning."""

    window_s: float = 10.0
    #: more than this share of the window's frames dropped: falling behind
    behind_share: float = 0.05
    #: at or under this share again: keeping up
    caught_up_share: float = 0.01
    #: fewer frames than this in the window (a start, a stalled camera) judge nothing
    min_frames: int = 60


@dataclass(frozen=True)
class Counts:
    """Frames processed and dropped over the watch's window, up to now."""

    frames: int
    dropped: int
    window_s: float

    @property
    def share(self) -> float:
        """Dropped over all the frames that came."""
        total = self.frames + self.dropped
        return self.dropped / total if total else 0.0


class KeepUpWatch:
    """The dropped share over a sliding window, and whether it says "falling behind"."""

    def __init__(self, policy: KeepUpPolicy | None = None) -> None:
        self.policy = policy or KeepUpPolicy()
        self.behind = False
        self.last: Counts | None = None
        self._samples: deque[tuple[float, int, int]] = deque()

    def update(self, now_s: float, frames: int, dropped: int) -> bool | None:
        """Record the running totals at ``now_s``: True when the processing has just
        fallen behind, False when it has just caught up again, None when nothing changed."""
        p = self.policy
        self._samples.append((now_s, frames, dropped))
        # keep the newest sample at least a window old as the window's start
        while len(self._samples) > 2 and now_s - self._samples[1][0] >= p.window_s:
            self._samples.popleft()
        t0, f0, d0 = self._samples[0]
        counts = Counts(frames - f0, dropped - d0, now_s - t0)
        if counts.frames + counts.dropped < p.min_frames:
            return None
        self.last = counts
        if not self.behind and counts.share > p.behind_share:
            self.behind = True
            return True
        if self.behind and counts.share <= p.caught_up_share:
            self.behind = False
            return False
        return None

    def warning(self) -> str | None:
        """The status's warning while falling behind, else None."""
        if not self.behind or self.last is None:
            return None
        c = self.last
        return (f"falling behind the camera: {c.dropped} of {c.frames + c.dropped} frames "
                f"dropped in the last {c.window_s:.0f} s ({100 * c.share:.0f} %)")
