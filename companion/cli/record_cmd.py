"""``companion record``: record any frame source into a recorded stream folder, and with
``--autopilot`` the autopilot's telemetry beside the frames (stream format version 2)."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import logging
from pathlib import Path
from typing import Any

from companion.cli import positive_seconds
from companion.core.stream_format import StreamMeta
from companion.core.stream_io import IMAGE_FORMATS, StreamWriter
from companion.errors import ConfigError
from companion.settings import Settings
from companion.sources.base import EndOfStream, FrameSource, KnowsTruthRows, monotonic_us
from companion.sources.config import SourceConfig
from companion.sources.factory import open_source, resolve
from companion.sources.files import RecordedStreamSource
from mavlink_bridge.bridge import VisionBridge
from mavlink_bridge.codec import MAVLinkMessage
from mavlink_bridge.fake_replay import REPLAYED
from tracker.camera import CameraModel

#: What ``--autopilot`` asks for (Hz): the messages the companion consumes
#: (companion.sensors, the autopilot's position for the plots) at the rates it asks in
#: flight (mavlink_bridge.streams.needed_streams), ATTITUDE at its 50 Hz.
TELEMETRY_RATES = (("ATTITUDE", 50.0), ("LOCAL_POSITION_NED", 10.0),
                   ("DISTANCE_SENSOR", 10.0), ("GLOBAL_POSITION_INT", 5.0))

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion record``."""
    parser = sub.add_parser(
        "record", help="record frames from any source into a stream folder",
        description="Record a camera (index, /dev/videoN, GStreamer pipeline, RTSP URL), a "
        "video file, an OTB folder, a stream folder or a simulated scenario into a recorded "
        "stream folder (docs/formats.md). A spec may be prefixed with its kind, e.g. "
        "camera:0, video:clip.mp4, sim:survey.",
    )
    parser.add_argument("--source", required=True, metavar="SPEC", help="what to record")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR")
    parser.add_argument("--seconds", type=positive_seconds, metavar="S",
                        help="stop after this much recorded time (default: until the end or "
                        "Ctrl-C)")
    parser.add_argument("--frames", type=int, metavar="N", help="stop after N frames")
    parser.add_argument("--format", choices=IMAGE_FORMATS, default="png",
                        help="png files (lossless, default), jpg files, or one lossless "
                        "FFV1 video (ffv1)")
    parser.add_argument("--fps", type=float, default=30.0,
                        help="frame rate written for sources without their own (default 30)")
    parser.add_argument("--stall-timeout", type=float, default=2.0, metavar="S",
                        help="give up on a live source silent for this long (default 2 s)")
    parser.add_argument("--jpeg-quality", type=int, default=95, metavar="Q",
                        help="JPEG quality 1-100 with --format jpg (default 95)")
    parser.add_argument("--autopilot", metavar="ENDPOINT",
                        help="also record the autopilot's telemetry (ATTITUDE, "
                        "LOCAL_POSITION_NED, DISTANCE_SENSOR, GLOBAL_POSITION_INT) from this "
                        "MAVLink endpoint, e.g. udpin:0.0.0.0:14550 (docs/replay.md)")
    parser.add_argument("--overwrite", action="store_true")
    parser.set_defaults(handler=run)


class TelemetryTap:
    """The autopilot's messages the companion consumes, as they arrive (monotonic us)."""

    def __init__(self, bridge: VisionBridge) -> None:
        link = getattr(bridge, "link", None)
        if link is None:
            raise ConfigError("record --autopilot needs mavlink.backend = \"pymavlink\"")
        self.items: list[tuple[int, str, dict[str, Any]]] = []
        link.add_msg_listener(self._on)

    def _on(self, msg: MAVLinkMessage) -> None:
        name = msg.get_type()
        if name in REPLAYED:
            fields = {k: v for k, v in msg.to_dict().items() if k != "mavpackettype"}
            self.items.append((monotonic_us(), name, fields))

    def drain(self) -> list[tuple[int, str, dict[str, Any]]]:
        out, self.items = self.items, []
        return out


def _meta(source: FrameSource, size: tuple[int, int], fps: float, spec: str,
          camera: CameraModel, camera_id: str) -> StreamMeta:
    """Keep a recorded stream's or a scenario's metadata; else the configured camera."""
    if isinstance(source, RecordedStreamSource):
        meta = source.meta
        return dataclasses.replace(meta, provenance={**meta.provenance, "recorded_from": spec})
    from companion.sim.source import SimCameraSource  # loaded by a simulated source already

    if isinstance(source, SimCameraSource):
        return source.sim.stream_meta()
    if (camera.width, camera.height) != size:  # scale the intrinsics to the real size
        sx, sy = size[0] / camera.width, size[1] / camera.height
        camera = dataclasses.replace(camera, width=size[0], height=size[1], fx=camera.fx * sx,
                                     fy=camera.fy * sy, cx=(camera.cx + 0.5) * sx - 0.5,
                                     cy=(camera.cy + 0.5) * sy - 0.5)
    return StreamMeta(fps=fps, camera=camera, camera_id=camera_id,
                      provenance={"recorded_from": spec, "camera_model": "from settings"})


async def record(config: SourceConfig, out: Path, camera: CameraModel, *, seconds: float | None,
                 frames: int | None, image_format: str, overwrite: bool,
                 jpeg_quality: int = 95, bridge: VisionBridge | None = None) -> int:
    """Copy frames from a source into a stream folder; returns the number written.

    With ``bridge`` (a link to the autopilot), its telemetry goes to ``telemetry.csv`` on the
    frames' clock: the first frame's arrival fixes the offset between the monotonic clock
    the messages arrive on and the frames' times (a live camera's frames carry their
    capture time on the monotonic clock: the offset is then its small delivery delay)."""
    tap = None if bridge is None else TelemetryTap(bridge)
    if bridge is not None:
        await bridge.start()
        if not await bridge.wait_link(True, 5.0):
            log.warning("record: no heartbeat from the autopilot at %s yet: recording the "
                        "frames, telemetry from when it comes", bridge.config.endpoint)
    source = await open_source(config)
    writer: StreamWriter | None = None
    count, first_t, offset_us = 0, None, 0
    try:
        while frames is None or count < frames:
            try:
                frame = await source.recv()
            except EndOfStream:
                break
            if first_t is None:
                first_t, offset_us = frame.t_us, monotonic_us() - frame.t_us
            if seconds is not None and frame.t_us - first_t >= seconds * 1e6:
                break
            if writer is None:
                meta = _meta(source, frame.size, config.fps, config.spec, camera,
                             config.camera_id)
                writer = StreamWriter(out, meta, image_format, jpeg_quality, overwrite=overwrite)
            truth = source.truth(frame.index) if isinstance(source, KnowsTruthRows) else None
            writer.write(frame, truth)
            count += 1
            for t_us, name, fields in [] if tap is None else tap.drain():
                if t_us - offset_us >= first_t:
                    writer.write_telemetry(t_us - offset_us, name, fields)
    finally:
        source.close()
        if writer is not None:
            writer.close()
        if bridge is not None:
            await bridge.stop()
    if source.status.skipped:
        log.warning("record: skipped %d frame(s): %s", source.status.skipped,
                    source.status.skip_reasons)
    return count


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Record until the source ends, --seconds/--frames, or Ctrl-C."""
    if args.frames is not None and args.frames < 1:
        raise ConfigError(f"--frames: expected an integer >= 1, got {args.frames}")
    config = resolve(SourceConfig(spec=args.source, realtime=False, fps=args.fps,
                                  stall_timeout_s=args.stall_timeout))
    if not 1 <= args.jpeg_quality <= 100:
        raise ConfigError(f"--jpeg-quality: expected 1-100, got {args.jpeg_quality}")
    if config.kind == "sim":  # simulated frames render as fast as they can be written,
        # or in real time beside a live autopilot's telemetry
        config = dataclasses.replace(config, realtime=args.autopilot is not None)
    bridge = None
    if args.autopilot is not None:
        from companion.runtime import bridge_for

        bridge = bridge_for(settings, endpoint=args.autopilot, streams=TELEMETRY_RATES,
                            set_origin=False)
    count = asyncio.run(record(config, args.out, settings.camera, seconds=args.seconds,
                               frames=args.frames, image_format=args.format,
                               overwrite=args.overwrite, jpeg_quality=args.jpeg_quality,
                               bridge=bridge))
    print(f"{args.out}: recorded {count} frames from {config.kind} {config.spec}")
    return 0
