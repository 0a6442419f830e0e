"""Configuration of the frame source (one frozen dataclass, validated by companion.settings)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

SourceKind = Literal["auto", "sim", "stream", "otb", "video", "camera", "follow"]


@dataclass(frozen=True)
class FollowConfig:
    """The simulated camera that follows an autopilot simulator's true pose (docs/sitl.md).

    ``truth_timeout_s``: at start, how long to wait for the first truth message before a
    one-line error names the missing message.  ``stale_ms``: truth older than this makes the
    camera stop delivering (a stale world must not produce fixes).  ``delay_ms``: frames show
    the world this long before their due time, so that two truth samples bracket it (the
    frame is stamped with that earlier time).  ``max_extrapolation_ms``: how far past the
    newest sample a frame may still be extrapolated.  ``request_rate_hz``: the truth
    message's rate asked of the autopilot with SET_MESSAGE_INTERVAL (0: do not ask).
    ``fps``: camera frame rate (0: the scenario's).
    """

    truth_timeout_s: float = field(default=10.0, metadata={"gt": 0})
    stale_ms: float = field(default=300.0, metadata={"gt": 0})
    delay_ms: float = field(default=20.0, metadata={"ge": 0, "le": 500})
    max_extrapolation_ms: float = field(default=100.0, metadata={"ge": 0})
    request_rate_hz: float = field(default=50.0, metadata={"ge": 0, "le": 400})
    fps: float = field(default=0.0, metadata={"ge": 0})


@dataclass(frozen=True)
class SourceConfig:
    """Where frames come from and how they are paced.

    ``spec``: a stream folder, an OTB folder, a video file, a camera (device index such as
    ``"0"``, a V4L2 path, a GStreamer pipeline or an RTSP URL) or, for ``kind = "sim"``, a
    scenario name (``config/scenarios/NAME.toml``) or a scenario file; for ``kind = "follow"``
    the scenario whose world (camera, effects, facades) is rendered from the autopilot
    simulator's true pose, with the landmarks of ``landmarks.map_path`` about the
    configured EKF origin (section ``[source.follow]``).  ``kind = "auto"``
    guesses from the spec (see :func:`companion.sources.factory.guess_kind`).
    ``realtime``: replay recorded times at their pace (false: as fast as possible).
    ``loop``: start again at the end of a finite source.  ``fps`` is used where the source
    has no times of its own (OTB folders, videos without timestamps, the simulator).
    ``camera_fps``: the frame rate to ask a live camera for (0: its own; a GStreamer
    pipeline states its rate in its caps instead, docs/deploy.md "The camera's frame rate
    comes first").
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
    camera_fps: float = field(default=0.0, metadata={"ge": 0, "le": 1000})
    stall_timeout_s: float = field(default=2.0, metadata={"gt": 0})
    open_timeout_s: float = field(default=5.0, metadata={"gt": 0})
    width: int = field(default=0, metadata={"ge": 0})  # 0 = camera default / scenario size
    height: int = field(default=0, metadata={"ge": 0})
    seed: int = field(default=0, metadata={"ge": 0})
    follow: FollowConfig = field(default_factory=FollowConfig)


def camera_rate_refusal(spec: str, fps: float) -> str | None:
    """Why ``source.camera_fps`` cannot be asked of the camera ``spec`` (None: it can):
    a GStreamer pipeline states its rate in its caps, a network stream's is set where it is
    sent (OpenCV cannot change either once open)."""
    s = spec.strip()
    if "!" in s:
        return ("a GStreamer pipeline sets its rate in its caps (... ! video/x-raw,"
                f"framerate={fps:g}/1 ! ...); leave source.camera_fps at 0")
    if "://" in s:
        return ("a network stream's rate is set where it is sent (the camera's or the "
                "server's settings); leave source.camera_fps at 0")
    return None
