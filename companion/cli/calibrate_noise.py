"""``companion calibrate noise``: the action of ``companion calibrate`` that measures the
pixel noise (:mod:`companion.noise`) on frames of the configured ``[source]``."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from companion.app import Frame
from companion.calibration_io import refuse_existing, write_atomically
from companion.errors import InputError
from companion.flightmap import load_practical_map
from companion.noise import measure_noise, noise_toml
from companion.perception import Perception
from companion.runtime import detector_for
from companion.settings import Settings
from companion.sources.base import EndOfStream
from companion.sources.config import SourceConfig
from companion.sources.factory import open_source


def register_action(actions: argparse._SubParsersAction) -> None:
    """Add ``companion calibrate noise``."""
    noise = actions.add_parser(
        "noise", help="measure the corner jitter of a landmark held still -> pixel_sigma_px",
        description="Read frames from the configured [source] (a camera, a recording), run "
        "the perception with the configured camera model and landmark map, measure the "
        "corner jitter of --landmark, and write a [pose] pixel_sigma_px layer to include in "
        "the vehicle's configuration.  The landmark and the camera must not move.")
    noise.add_argument("--landmark", required=True, metavar="ID", help="a landmark of the map")
    noise.add_argument("--out", type=Path, required=True, metavar="FILE.toml")
    noise.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    noise.add_argument("--frames", type=int, default=150, help="frames to read (default 150)")
    noise.set_defaults(handler=run)


def source_frames(config: SourceConfig, count: int) -> Iterator[Frame]:
    """Up to ``count`` frames of a source, read on a private event loop (recordings as
    fast as they can be read)."""
    loop = asyncio.new_event_loop()
    try:
        source = loop.run_until_complete(open_source(
            dataclasses.replace(config, realtime=False)))
        try:
            for _ in range(count):
                try:
                    yield loop.run_until_complete(source.recv())
                except EndOfStream:
                    return
        finally:
            source.close()
    finally:
        loop.close()


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Measure and write."""
    refuse_existing(args.out, args.overwrite)
    pmap = load_practical_map(settings)
    if args.landmark not in {lm.landmark_id for lm in pmap.landmarks}:
        raise InputError(f"calibrate noise: no landmark {args.landmark!r} in "
                         f"{settings.landmarks.map_path}")
    perception = Perception(settings.camera, pmap.landmarks, pmap.references,
                            detect=detector_for(settings), config=settings.perception,
                            tracker_config=settings.tracker, pose_config=settings.pose,
                            acquire_config=settings.acquire, gate_config=settings.fixgate)
    try:
        result = measure_noise(perception, source_frames(settings.source, args.frames),
                               args.landmark,
                               lambda line: print(f"calibrate noise: {line}", file=sys.stderr))
    finally:
        perception.close()
    print(f"landmark {result.landmark_id}: {result.frames_used} of {result.frames_read} frames "
          f"with corners, plate {result.plate_width_px:.0f} px wide, drift "
          f"{result.drift_px:.2f} px")
    print(f"corner jitter {result.jitter_px:.4f} px -> pose.pixel_sigma_px = "
          f"{result.pixel_sigma_px:.4f}")
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    camera_file = settings.origin_of("camera.fx")
    write_atomically(args.out, noise_toml(result, camera_file, when), args.overwrite)
    print(f"wrote {args.out} (include it in the vehicle's configuration)")
    return 0

