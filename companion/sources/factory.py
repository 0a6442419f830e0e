"""Open any frame source from a :class:`SourceConfig` or a command-line spec."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

from companion.core.resources import scenario_path
from companion.errors import InputError
from companion.sources.base import FrameSource
from companion.sources.config import SourceConfig, SourceKind
from companion.sources.files import OtbSource, RecordedStreamSource
from companion.sources.live import VIDEO_SUFFIXES, CameraSource, VideoFileSource

KINDS = ("sim", "stream", "otb", "video", "camera", "follow")

#: Opens the simulated camera (kind ``sim``) for a resolved config. The frame sources do not
#: import the simulator (docs/architecture.md): a command that offers simulated sources
#: passes :func:`companion.simulated.open_sim` to :func:`open_source`.
SimOpener = Callable[[SourceConfig], FrameSource]


def split_spec(spec: str) -> tuple[SourceKind, str]:
    """``"kind:rest"`` -> (kind, rest) for a known kind, else ("auto", spec).

    URLs (``rtsp://``) are not mistaken for a kind prefix.
    """
    head, sep, rest = spec.partition(":")
    if sep and head in KINDS and not rest.startswith("//"):
        return head, rest  # type: ignore[return-value]
    return "auto", spec


def guess_kind(spec: str) -> SourceKind:
    """What a spec names: a camera (digits, /dev/..., a URL, a GStreamer pipeline), a stream
    folder (has stream.toml), an OTB folder (has img/), a video file, or a scenario."""
    s = spec.strip()
    if s.isdigit() or s.startswith("/dev/") or "://" in s or "!" in s:
        return "camera"
    path = Path(s).expanduser()
    if path.is_dir():
        if (path / "stream.toml").exists():
            return "stream"
        if (path / "img").is_dir():
            return "otb"
        raise InputError(f"{s}: folder is neither a recorded stream nor an OTB sequence")
    if path.suffix.lower() in VIDEO_SUFFIXES:
        return "video"
    if scenario_path(s).exists():
        return "sim"
    raise InputError(
        f"{s}: not a camera, stream folder, OTB folder, video file or scenario "
        "(prefix it with sim:, stream:, otb:, video: or camera:)"
    )


def resolve(config: SourceConfig) -> SourceConfig:
    """The config with ``kind`` decided (a ``kind:`` prefix in ``spec`` wins over auto)."""
    kind, spec = split_spec(config.spec)
    if kind == "auto":
        kind = config.kind if config.kind != "auto" else guess_kind(spec)
    return dataclasses.replace(config, kind=kind, spec=spec)


async def open_source(config: SourceConfig, simulated: SimOpener | None = None) -> FrameSource:
    """Open the source a config names; one-line :class:`InputError`/``SourceError`` if not.

    ``simulated`` opens a scenario (kind ``sim``); without it a scenario is refused.
    """
    c = resolve(config)
    if c.kind == "follow":
        raise InputError("source.kind = \"follow\": the camera follows an autopilot "
                         "simulator's truth, so it needs the MAVLink link: use `companion run` "
                         "(docs/sitl.md)")
    if c.kind == "stream":
        return RecordedStreamSource(Path(c.spec), realtime=c.realtime, loop=c.loop,
                                    speed=c.speed)
    if c.kind == "otb":
        return OtbSource(Path(c.spec), fps=c.fps, realtime=c.realtime, loop=c.loop,
                         speed=c.speed, camera_id=c.camera_id)
    if c.kind == "video":
        return VideoFileSource(Path(c.spec), realtime=c.realtime, loop=c.loop, speed=c.speed,
                               fps=c.fps, camera_id=c.camera_id)
    if c.kind == "camera":
        size = (c.width, c.height) if c.width and c.height else None
        return await CameraSource.open(c.spec, open_timeout_s=c.open_timeout_s,
                                       camera_id=c.camera_id, stall_timeout_s=c.stall_timeout_s,
                                       size=size)
    if simulated is None:
        raise InputError(f"{c.spec}: a simulated camera (source kind sim) is not available "
                         "here; use a stream, OTB folder, video or camera")
    return simulated(c)
