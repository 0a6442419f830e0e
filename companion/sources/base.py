"""The frame contract shared by every source, status counters and replay pacing.

The records themselves (:class:`Frame`, :data:`ImageU8`, :class:`SourceStatus`,
:class:`EndOfStream`, :func:`monotonic_us`) live in :mod:`companion.core.frames`, which the
simulator imports too; they are imported here so that a source needs one module.

A source that knows more than its frames says so through a protocol, so that a flight
picks it up without knowing what kind of source it is (``companion run`` never imports
the simulator): :class:`KnowsTruth` (where the vehicle truly was), :class:`KnowsReferences`
(its landmarks' appearance images), :class:`KnowsCamera` (the camera that took it) and
:class:`KnowsTruthRows` (a frame's truth row, as a recorded stream stores it).
"""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from companion.core.frames import EndOfStream, Frame, ImageU8, SourceStatus, monotonic_us

if TYPE_CHECKING:
    from companion.core.stream_format import FrameTruth
    from tracker.camera import CameraModel

__all__ = ["EndOfStream", "Frame", "FrameSource", "ImageU8", "KnowsCamera", "KnowsReferences",
           "KnowsTruth", "KnowsTruthRows", "Pacer", "SourceStatus", "monotonic_us"]


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


@runtime_checkable
class KnowsTruth(Protocol):
    """A source that knows where the vehicle truly was (a simulated camera)."""

    def truth_position(self, frame: Frame) -> tuple[float, float, float] | None:
        """The vehicle's true position (flight NED, m) when ``frame`` was taken; None when
        unknown (e.g. a frame too old to be remembered)."""
        ...


@runtime_checkable
class KnowsReferences(Protocol):
    """A source whose landmarks' appearance it knows (a simulated world's textures)."""

    def reference_images(self) -> dict[str, ImageU8]:
        """Landmark id -> its appearance reference image."""
        ...


@runtime_checkable
class KnowsCamera(Protocol):
    """A source that says which camera took its frames (a simulated scenario's)."""

    def camera_model(self) -> CameraModel:
        """The camera model (intrinsics, mount) of the frames."""
        ...


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


@runtime_checkable
class KnowsTruthRows(Protocol):
    """A source that has each frame's truth row (a simulated camera, a recorded stream with
    ``truth_pose.csv``): what ``companion record`` writes beside the frame."""

    def truth(self, index: int) -> FrameTruth | None:
        """Frame ``index``'s truth (pose, landmark boxes); None when it has none."""
        ...
