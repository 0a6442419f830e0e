"""Frame sources: recorded streams, OTB folders, video files, live cameras, the simulator.

Every source is a :class:`~companion.sources.base.FrameSource`: ``await source.recv()``
returns the next :class:`~companion.sources.base.Frame` and raises
:class:`~companion.sources.base.EndOfStream` when a finite source is exhausted.
"""

from companion.sources.base import EndOfStream, Frame, FrameSource, SourceStatus

__all__ = ["EndOfStream", "Frame", "FrameSource", "SourceStatus"]
