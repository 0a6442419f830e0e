"""``companion record``: record any frame source into a recorded stream folder."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import logging
from pathlib import Path

from companion.cli import positive_seconds
from companion.errors import ConfigError
from companion.settings import Settings
from companion.sim.source import SimCameraSource
from companion.sources.base import EndOfStream, FrameSource
from companion.sources.config import SourceConfig
from companion.sources.factory import open_source, resolve
from companion.sources.files import RecordedStreamSource
from companion.sources.stream_format import StreamMeta
from companion.sources.stream_io import IMAGE_FORMATS, StreamWriter
from tracker.camera import CameraModel

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
    parser.add_argument("--overwrite", action="store_true")
    parser.set_defaults(handler=run)


def _meta(source: FrameSource, size: tuple[int, int], fps: float, spec: str,
          camera: CameraModel, camera_id: str) -> StreamMeta:
    """Keep a recorded stream's or a scenario's metadata; else the configured camera."""
    if isinstance(source, RecordedStreamSource):
        meta = source.meta
        return dataclasses.replace(meta, provenance={**meta.provenance, "recorded_from": spec})
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
                 frames: int | None, image_format: str, overwrite: bool) -> int:
    """Copy frames from a source into a stream folder; returns the number written."""
    source = await open_source(config)
    writer: StreamWriter | None = None
    count, first_t = 0, None
    try:
        while frames is None or count < frames:
            try:
                frame = await source.recv()
            except EndOfStream:
                break
            first_t = frame.t_us if first_t is None else first_t
            if seconds is not None and frame.t_us - first_t >= seconds * 1e6:
                break
            if writer is None:
                meta = _meta(source, frame.size, config.fps, config.spec, camera,
                             config.camera_id)
                writer = StreamWriter(out, meta, image_format, overwrite=overwrite)
            truth = None
            if isinstance(source, SimCameraSource | RecordedStreamSource):
                truth = source.truth(frame.index)
            writer.write(frame, truth)
            count += 1
    finally:
        source.close()
        if writer is not None:
            writer.close()
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
    if config.kind == "sim":  # simulated frames render as fast as they can be written
        config = dataclasses.replace(config, realtime=False)
    count = asyncio.run(record(config, args.out, settings.camera, seconds=args.seconds,
                               frames=args.frames, image_format=args.format,
                               overwrite=args.overwrite))
    print(f"{args.out}: recorded {count} frames from {config.kind} {config.spec}")
    return 0
