"""Open any frame source from a :class:`SourceConfig` or a command-line spec.

The kinds of the frame sources here (stream, otb, video, camera) are built in.  The
simulator's kinds (``sim``, ``follow``) are *plugged in*: :func:`companion.simulated.register`
puts their openers in this module's registry.  The command line names the module that
provides each kind (``companion.cli.PLUGINS``, :func:`plug_in_module`), and the module is
imported only when a source of that kind is opened: neither the sources nor a ``companion
run`` on a camera or a stream import the simulator (docs/architecture.md, "Packages and the
direction of imports"; ``tests/test_import_layers.py`` checks the running process).
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from companion.core.resources import scenario_path
from companion.errors import InputError
from companion.sources.base import FrameSource
from companion.sources.config import SourceConfig, SourceKind
from companion.sources.files import OtbSource, RecordedStreamSource
from companion.sources.live import VIDEO_SUFFIXES, CameraSource, VideoFileSource

if TYPE_CHECKING:
    from companion.landmarks.geodesy import LocalFrame

KINDS = ("sim", "stream", "otb", "video", "camera", "follow")



@dataclass(frozen=True)
class OpenContext:
    """What a plugged-in source may need of the flight beyond its configuration: follow
    mode renders the world of the flight's map (``map_path``) about its EKF ``origin``,
    from the true pose the autopilot simulator reports over ``link`` (the MAVLink bridge)
    in its ``profile``'s messages.  A command without a link passes none."""

    link: object | None = None
    origin: LocalFrame | None = None
    map_path: str = ""
    profile: str = "ardupilot"


#: Opens a plugged-in source kind: (resolved config, context) -> the source.
Opener = Callable[[SourceConfig, OpenContext], FrameSource]
_PLUGGED: dict[str, Opener] = {}
#: kind -> the module whose ``register()`` plugs it in, imported when first opened
_PROVIDERS: dict[str, str] = {}


def plug_in(kind: SourceKind, opener: Opener) -> None:
    """Open source ``kind`` with ``opener`` from now on (idempotent)."""
    _PLUGGED[kind] = opener


def plug_in_module(kind: SourceKind, module: str) -> None:
    """Source ``kind`` is provided by ``module`` (its ``register()`` plugs the opener in),
    imported only when a source of that kind is first opened."""
    _PROVIDERS[kind] = module


def _opener(kind: str) -> Opener | None:
    if kind not in _PLUGGED and kind in _PROVIDERS:
        importlib.import_module(_PROVIDERS[kind]).register()
    return _PLUGGED.get(kind)


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


async def open_source(config: SourceConfig, context: OpenContext | None = None
                      ) -> FrameSource:
    """Open the source a config names; one-line :class:`InputError`/``SourceError`` if not.

    A plugged-in kind (:func:`plug_in`) is opened with ``context``; one nobody plugged in
    is refused.
    """
    c = resolve(config)
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
                                       size=size, fps=c.camera_fps or None)
    opener = _opener(c.kind)
    if opener is None:
        raise InputError(f"{c.spec}: a simulated camera (source kind {c.kind}) is not "
                         "available here; use a stream, OTB folder, video or camera")
    return opener(c, context or OpenContext())
