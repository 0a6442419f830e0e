"""``companion run``: the real deployment -- a camera and a serial or UDP autopilot link."""

from __future__ import annotations

import argparse
import asyncio
import logging

from companion.app import CompanionApp
from companion.autopilot import AttitudeHistory
from companion.perception import Perception
from companion.runtime import PracticalMap, bridge_for, fly, load_practical_map, perception_for
from companion.settings import Settings
from companion.sim.source import SimCameraSource
from companion.sources.factory import open_source

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion run``."""
    parser = sub.add_parser(
        "run", help="fly: camera -> trackers -> pose -> MAVLink to the autopilot",
        description="Run the companion with the configured source ([source]), landmark map "
        "([landmarks] map_path), autopilot link ([mavlink]) and monitoring ([monitor]) until "
        "SIGINT/SIGTERM or the end of a finite source.  docs/deploy.md has a systemd unit.",
    )
    parser.add_argument("--seconds", type=float, help="stop after this many seconds")
    parser.set_defaults(handler=run)


def with_sim_references(pmap: PracticalMap, source: object) -> PracticalMap:
    """A simulated camera shows generated textures: use them where the map has no image."""
    if not isinstance(source, SimCameraSource):
        return pmap
    textures = {lm.landmark_id: lm.quad.texture for lm in source.sim.world.landmarks
                if lm.quad.texture is not None}
    refs = {**{k: v for k, v in textures.items() if k not in pmap.references},
            **pmap.references}
    return PracticalMap(pmap.landmarks, refs, pmap.origin)


async def _run(settings: Settings, seconds: float | None) -> CompanionApp:
    pmap = load_practical_map(settings)
    source = await open_source(settings.source)
    pmap = with_sim_references(pmap, source)
    camera = source.sim.scenario.camera if isinstance(source, SimCameraSource) \
        else settings.camera
    log.info("flying with %d landmarks (%d with a reference image), source %s:%s",
             len(pmap.landmarks), len(pmap.references), settings.source.kind,
             settings.source.spec)

    def processor(attitude: AttitudeHistory) -> Perception:
        return perception_for(settings, camera, pmap, attitude)

    return await fly(settings, source, bridge_for(settings), processor, pmap.landmarks,
                     seconds=seconds, prefix="run")


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Fly until stopped; exit status 0 on a clean stop."""
    app = asyncio.run(_run(settings, args.seconds))
    c = app.counters
    log.info("stopped: %d frames, %d fixes sent, %d dropped frames", c.frames, c.fixes_sent,
             app.dropped_frames)
    return 0
