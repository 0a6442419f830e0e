"""``companion run``: the real deployment -- a camera and a serial or UDP autopilot link."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import logging
import sys
from dataclasses import dataclass

from companion.app import CompanionApp, FrameSource
from companion.autopilot import outcome_lines
from companion.cli import positive_seconds
from companion.config_checks import preflight
from companion.errors import EXIT_FAILURE, EXIT_OK, ConfigError, SourceError
from companion.flightmap import PracticalMap, load_practical_map
from companion.nofix import AttitudeSource
from companion.observers import TruthOf, TruthTags
from companion.recorded import (
    RECORDED_KINDS,
    OnCompanionClock,
    RecordedTruth,
    TruthAttitude,
    recording_camera,
)
from companion.runtime import CompanionFlight, bridge_for
from companion.settings import Settings
from companion.sources.base import KnowsCamera, KnowsReferences, KnowsTruth
from companion.sources.factory import OpenContext, open_source, resolve
from companion.sources.files import RecordedStreamSource
from companion.square import FlightAbortedError, SquareFlight
from mavlink_bridge.bridge import VisionBridge
from tracker.camera import CameraModel

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion run``."""
    parser = sub.add_parser(
        "run", help="fly: camera -> trackers -> pose -> MAVLink to the autopilot",
        description="Run the companion with the configured source ([source]), landmark map "
        "(the practical map of [landmarks] db_path about the EKF origin, or the file "
        "[landmarks] map_path when set), autopilot link ([mavlink]) and monitoring "
        "([monitor]) until SIGINT/SIGTERM or the end of a finite source.  docs/deploy.md "
        "has a systemd unit.",
    )
    parser.add_argument("--seconds", type=positive_seconds, help="stop after this many seconds")
    parser.add_argument("--truth-attitude", action="store_true",
                        help="a recorded stream with truth_pose.csv: take the attitude from "
                        "it (with an autopilot's typical error) instead of the autopilot's "
                        "ATTITUDE, to check a recording offline (docs/formats.md)")
    parser.add_argument("--fly", action="store_true",
                        help="SITL only: arm (GUIDED / OFFBOARD) and fly a small square with "
                        "position targets so the loop runs while moving (docs/sitl.md)")
    parser.set_defaults(handler=run)


def with_source_references(pmap: PracticalMap, source: object) -> PracticalMap:
    """A source that knows its landmarks' appearance (a simulated camera shows generated
    textures: :class:`KnowsReferences`) fills in where the map has no image."""
    if not isinstance(source, KnowsReferences):
        return pmap
    refs = {**{k: v for k, v in source.reference_images().items() if k not in pmap.references},
            **pmap.references}
    unusable = {k: v for k, v in pmap.unusable.items() if k not in refs}
    return dataclasses.replace(pmap, references=refs, unusable=unusable)


@dataclass(frozen=True)
class RunSource:
    """The frames of a run, the camera that took them, where their attitude comes from
    (None: the autopilot's ATTITUDE) and their true position when known."""

    source: FrameSource
    camera: CameraModel
    attitude: AttitudeSource | None = None
    truth_of: TruthOf | None = None


async def open_run_source(settings: Settings, bridge: VisionBridge, pmap: PracticalMap,
                          truth_attitude: bool = False) -> RunSource:
    """The configured source; a recording is put on the companion's clock, solved with its
    own camera and, with truth, scored against it (:mod:`companion.recorded`).  A source
    that says which camera took it or knows its truth (a simulated camera, through the
    protocols of :mod:`companion.sources.base`) is taken at its word."""
    c = resolve(settings.source)
    log.info("source %s:%s", c.kind, c.spec)
    if truth_attitude and c.kind != "stream":
        raise ConfigError(f"--truth-attitude: source {c.spec!r} is a {c.kind}, not a recorded "
                          "stream with truth_pose.csv")
    source = await open_source(settings.source, OpenContext(
        bridge, pmap.origin, settings.landmarks.map_path, settings.vehicle.profile))
    if c.kind not in RECORDED_KINDS:
        camera = source.camera_model() if isinstance(source, KnowsCamera) else settings.camera
        truth_of = source.truth_position if isinstance(source, KnowsTruth) else None
        return RunSource(source, camera, truth_of=truth_of)
    clocked = OnCompanionClock(source)
    camera = recording_camera(settings.camera, source, c.spec)
    if not isinstance(source, RecordedStreamSource):
        return RunSource(clocked, camera)
    truth = RecordedTruth(clocked, source, pmap.origin)
    return RunSource(clocked, camera, TruthAttitude(truth) if truth_attitude else None,
                     (lambda f: truth.position(f.t_us)) if truth else None)


async def _run(settings: Settings, seconds: float | None, fly_square: bool = False,
               truth_attitude: bool = False) -> CompanionApp:
    pmap = load_practical_map(settings)
    bridge = bridge_for(settings)
    run_source = await open_run_source(settings, bridge, pmap, truth_attitude)
    source = run_source.source
    flight = CompanionFlight(settings, source, bridge, with_source_references(pmap, source),
                             run_source.camera, attitude=run_source.attitude, prefix="run")
    if run_source.truth_of is not None:
        flight.observe(TruthTags(run_source.truth_of))
    flights: list[asyncio.Task[None]] = []

    def start_flying(app: CompanionApp) -> None:
        link = getattr(bridge, "link", None)
        if link is None:
            log.error("--fly needs mavlink.backend = \"pymavlink\"; not flying")
            return
        square = SquareFlight(link, bridge.latest, settings.vehicle.profile)
        flights.append(asyncio.create_task(square.run(), name="fly-square"))
        flights[0].add_done_callback(lambda task: _flight_ended(task, app))

    try:
        app = await flight.run(seconds, on_start=start_flying if fly_square else None)
    finally:
        for task in flights:
            task.cancel()
        outcomes = await asyncio.gather(*flights, return_exceptions=True)
    failure = getattr(source, "failure", None)
    if failure is not None:  # e.g. follow mode without the simulator's truth: one line
        raise failure
    aborted = [o for o in outcomes if isinstance(o, FlightAbortedError)]
    if aborted:  # the vehicle left the square's control: say why, exit non-zero
        raise aborted[0]
    return app


def _flight_ended(task: asyncio.Task[None], app: CompanionApp) -> None:
    """--fly ended by itself: a disarm, mode change or failsafe stops the companion too."""
    if task.cancelled() or task.exception() is None:
        return
    log.error("%s", task.exception())
    if isinstance(task.exception(), FlightAbortedError):
        app.request_stop()


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Fly until stopped: 0 at the end of a finite source or ``--seconds``, 128 + N when
    signal N stopped it (the CLI's root), 1 when the frame source failed for good (so
    systemd's ``Restart=on-failure`` restarts it), 2 for what :func:`preflight` refuses."""
    preflight(settings)
    app = asyncio.run(_run(settings, args.seconds, getattr(args, "fly", False),
                           getattr(args, "truth_attitude", False)))
    c = app.counters
    line, none_sent = outcome_lines(getattr(app.sink, "results", {}))
    log.info("stopped: %d frames, %s, %d dropped frames", c.frames, line, app.dropped_frames)
    if none_sent is not None:
        log.warning("%s", none_sent)
    if app.blocker is not None:
        log.warning("no fix could come: %s: %s", app.blocker.cause, app.blocker.detail)
    if c.worker_errors:  # a bug, logged with its traceback: not a clean stop
        print("companion: frame processing failed (see the log above)", file=sys.stderr)
        return EXIT_FAILURE
    if app.source_failure is not None:
        raise SourceError(f"frame source failed: {app.source_failure}")
    return EXIT_OK
