"""Configuration of the frame source (one frozen dataclass, validated by companion.settings)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

SourceKind = Literal["auto", "sim", "stream", "otb", "video", "camera"]


@dataclass(frozen=True)
class SourceConfig:
    """Where frames come from and how they are paced.

    ``spec``: a stream folder, an OTB folder, a video file, a camera (device index such as
    ``"0"``, a V4L2 path, a GStreamer pipeline or an RTSP URL) or, for ``kind = "sim"``, a
    scenario name (``config/scenarios/NAME.toml``) or a scenario file.  ``kind = "auto"``
    guesses from the spec (see :func:`companion.sources.factory.guess_kind`).
    ``realtime``: replay recorded times at their pace (false: as fast as possible).
    ``loop``: start again at the end of a finite source.  ``fps`` is used where the source
    has no times of its own (OTB folders, videos without timestamps, the simulator).
    ``stall_timeout_s``: a live source that delivers nothing for this long raises
    :class:`~companion.sources.live.SourceStallError` (and counts a stall).
    """

    kind: SourceKind = "auto"
    spec: str = "survey"
    camera_id: str = "cam0"
    realtime: bool = True
    loop: bool = False
    speed: float = field(default=1.0, metadata={"gt": 0})
    fps: float = field(default=30.0, metadata={"gt": 0})
    stall_timeout_s: float = field(default=2.0, metadata={"gt": 0})
    open_timeout_s: float = field(default=5.0, metadata={"gt": 0})
    width: int = field(default=0, metadata={"ge": 0})  # 0 = camera default / scenario size
    height: int = field(default=0, metadata={"ge": 0})
    seed: int = field(default=0, metadata={"ge": 0})
