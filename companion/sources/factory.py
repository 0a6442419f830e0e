"""Open any frame source from a :class:`SourceConfig` or a command-line spec."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from companion.errors import InputError
from companion.sources.base import FrameSource
from companion.sources.config import SourceConfig, SourceKind
from companion.sources.files import OtbSource, RecordedStreamSource
from companion.sources.live import VIDEO_SUFFIXES, CameraSource, VideoFileSource

KINDS = ("sim", "stream", "otb", "video", "camera", "follow")


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
    from companion.sim.scenario import scenario_path

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


async def open_source(config: SourceConfig) -> FrameSource:
    """Open the source a config names; one-line :class:`InputError`/``SourceError`` if not."""
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
    return open_sim(c)


def open_sim(c: SourceConfig) -> FrameSource:
    """The simulated camera for a scenario name or file."""
    from companion.sim.scenario import load_scenario
    from companion.sim.simulator import Simulator
    from companion.sim.source import SimCameraSource

    scenario = load_scenario(c.spec)
    if c.seed:
        scenario = dataclasses.replace(scenario, seed=c.seed)
    return SimCameraSource(Simulator(scenario), realtime=c.realtime, loop=c.loop)
